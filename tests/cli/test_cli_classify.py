"""``lidar2city classify`` through click's CliRunner."""


import laspy
import numpy as np

from lidar2city.cli.main import cli


def _write_scene(path, *, with_ground=True, n_extra=0):
    """A 40 m x 40 m tile in metres: ground, a 12 m x 12 m flat roof at 5 m, a tree."""
    rng = np.random.default_rng(0)
    xs, ys = np.meshgrid(np.arange(0, 40, 0.4), np.arange(0, 40, 0.4))
    g = np.column_stack([xs.ravel(), ys.ravel()]) + rng.uniform(-0.1, 0.1, (xs.size, 2))
    roof_area = (g[:, 0] > 10) & (g[:, 0] < 22) & (g[:, 1] > 10) & (g[:, 1] < 22)
    ground = np.column_stack([g[~roof_area], rng.normal(0, 0.02, (~roof_area).sum())])
    roof = np.column_stack([g[roof_area], 5 + rng.normal(0, 0.02, roof_area.sum())])
    d = rng.normal(size=(600, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tree = np.array([32.0, 32.0, 6.0]) + 2.5 * d * rng.uniform(0.5, 1.0, (600, 1))
    xyz = np.concatenate([ground, roof, tree])
    cls = np.concatenate([np.full(len(ground), 2 if with_ground else 1),
                          np.ones(len(roof) + len(tree))]).astype(np.uint8)
    nr = np.concatenate([np.ones(len(ground) + len(roof)), np.full(len(tree), 3)]).astype(np.uint8)
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([85000.0, 447000.0, 0.0])
    las = laspy.LasData(header)
    las.x = xyz[:, 0] + 85000
    las.y = xyz[:, 1] + 447000
    las.z = xyz[:, 2]
    las.classification = cls
    las.number_of_returns = nr
    las.return_number = np.ones(len(xyz), np.uint8)
    las.intensity = np.arange(len(xyz)) % 60000
    las.write(str(path))
    return len(ground), len(roof), len(tree)


def _one_line_error(res):
    assert res.exit_code == 1, res.output
    out = res.output.strip()
    assert out.startswith("Error:"), out
    assert len(out.splitlines()) == 1, out


def test_classify_ground_from_file(runner, tmp_path):
    src, dst = tmp_path / "in.las", tmp_path / "out.laz"
    n_ground, n_roof, n_tree = _write_scene(src)
    res = runner.invoke(cli, ["classify", str(src), "-o", str(dst), "--crs", "EPSG:28992",
                              "--ground-from-file"])
    assert res.exit_code == 0, res.output
    assert "points classified" in res.output
    before, after = laspy.read(str(src)), laspy.read(str(dst))
    assert len(after.points) == len(before.points)
    assert np.array_equal(after.intensity, before.intensity)
    assert np.array_equal(after.x, before.x)
    cls = np.asarray(after.classification)
    assert np.all(cls[:n_ground] == 2)
    assert (cls[n_ground:n_ground + n_roof] == 6).mean() > 0.98
    assert (cls[n_ground + n_roof:] == 5).mean() > 0.9
    assert after.header.parse_crs() is not None


def test_classify_config_file(runner, tmp_path):
    src, dst = tmp_path / "in.las", tmp_path / "out.las"
    _write_scene(src)
    cfg = tmp_path / "run.toml"
    cfg.write_text("[classify]\nmin_building_area = 500.0\n")
    res = runner.invoke(cli, ["classify", str(src), "-o", str(dst), "--ground-from-file",
                              "--config", str(cfg)])
    assert res.exit_code == 0, res.output
    assert not np.any(np.asarray(laspy.read(str(dst)).classification) == 6)
    cfg.write_text("[classify]\nmin_buildng_area = 5.0\n")
    res = runner.invoke(cli, ["classify", str(src), "-o", str(dst), "--ground-from-file",
                              "--config", str(cfg)])
    _one_line_error(res)
    assert "classify.min_buildng_area" in res.output
    cfg.write_text("[classify]\nmin_height = -2.0\n")
    _one_line_error(runner.invoke(cli, ["classify", str(src), "-o", str(dst),
                                        "--ground-from-file", "--config", str(cfg)]))


def test_classify_bad_inputs(runner, tmp_path):
    dst = tmp_path / "out.laz"
    _one_line_error(runner.invoke(cli, ["classify", str(tmp_path / "missing.laz"), "-o", str(dst),
                                        "--ground-from-file"]))
    txt = tmp_path / "notlas.laz"
    txt.write_text("hello")
    _one_line_error(runner.invoke(cli, ["classify", str(txt), "-o", str(dst), "--ground-from-file"]))
    empty = tmp_path / "empty.las"
    laspy.LasData(laspy.LasHeader(point_format=1, version="1.2")).write(str(empty))
    _one_line_error(runner.invoke(cli, ["classify", str(empty), "-o", str(dst), "--ground-from-file"]))
    noground = tmp_path / "noground.las"
    _write_scene(noground, with_ground=False)
    res = runner.invoke(cli, ["classify", str(noground), "-o", str(dst), "--ground-from-file"])
    _one_line_error(res)
    assert "ground" in res.output
    assert not dst.exists()
    assert not list(tmp_path.glob(".out*"))  # no temporary left behind
