import json


def test_evaluate_model_synthetic(runner, tmp_path):
    from test_cli_reconstruct import _synthetic_inputs

    from lidar2city.cli.main import cli

    las, gpkg, _ = _synthetic_inputs(tmp_path)
    out = tmp_path / "o.city.json"
    assert runner.invoke(cli, ["reconstruct", str(las), "--footprints", str(gpkg), "-o", str(out)]).exit_code == 0
    res = runner.invoke(cli, ["evaluate", "model", str(out), "--points", str(las), "--json"])
    assert res.exit_code == 0, res.output
    rep = json.loads(res.output)
    assert rep["summary"]["measured"] == 3 and rep["summary"]["valid"] == 3
    assert rep["summary"]["rmse_median"] < 0.1
