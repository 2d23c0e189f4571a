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


def test_evaluate_model_with_points_of_another_area(runner, tmp_path):
    """Points that miss every building of the model (another tile, another CRS)
    printed '0 measured: RMSE median None m' with exit 0: an error now."""
    import laspy
    import numpy as np
    from test_cli_reconstruct import _synthetic_inputs

    from lidar2city.cli.main import cli

    las, gpkg, _ = _synthetic_inputs(tmp_path)
    out = tmp_path / "o.city.json"
    res = runner.invoke(cli, ["reconstruct", str(las), "--footprints", str(gpkg), "-o", str(out)])
    assert res.exit_code == 0, res.output
    moved = laspy.read(las)
    moved.x = np.asarray(moved.x) + 3000.0
    moved.write(tmp_path / "far.las")
    res = runner.invoke(cli, ["evaluate", "model", str(out), "--points", str(tmp_path / "far.las")])
    assert res.exit_code == 1, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error:") and "none of the model's" in lines[0]
