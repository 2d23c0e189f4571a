import json


def test_demo_runs_end_to_end(runner, tmp_path):
    from lidar2city.cli.main import cli

    res = runner.invoke(cli, ["demo", "-o", str(tmp_path / "d")])
    assert res.exit_code == 0, res.output
    out = res.output
    assert "roof type right" in out and "solids valid" in out
    doc = json.loads((tmp_path / "d" / "town.city.json").read_text())
    assert doc["type"] == "CityJSON" and doc["version"] == "2.0"
    # every building has LoD1.2 and LoD2.2 geometry
    lods = [{g["lod"] for g in o["geometry"]} for o in doc["CityObjects"].values()]
    assert all(lod >= {"1.2", "2.2"} for lod in lods)


def test_demo_report_close_to_truth(tmp_path):
    from lidar2city.tools.demo import run_demo

    rep = run_demo(tmp_path, seed=3, density=8.0)
    m = rep.metrics
    assert m["valid"] == m["n_solids"]
    assert m["building_f1"] > 0.97
    assert m["footprints"]["quality"] > 0.9
    assert m["lod22_rmse"] < 0.15 < m["lod12_rmse"]
    assert m["roof_type_right"] >= m["n_buildings"] - 1
