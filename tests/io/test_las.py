import numpy as np
import pytest

from lidar2city.errors import CRSError, FileFormatError
from lidar2city.io.las import read_las, read_points, write_las


def test_missing_file(tmp_path):
    with pytest.raises(FileFormatError, match="no such file"):
        read_las(tmp_path / "nope.laz")


def test_not_a_las(tmp_path):
    p = tmp_path / "x.las"
    p.write_text("hello")
    with pytest.raises(FileFormatError, match="not a readable LAS"):
        read_las(p)


@pytest.mark.parametrize("head, says", [
    (b"ply\nformat binary_little_endian 1.0\n", "PLY point cloud"),
    (b"II*\x00\x08\x00\x00\x00", "GeoTIFF raster"),
    (b"SQLite format 3\x00", "--footprints")])
def test_a_file_of_another_format_is_named(tmp_path, head, says):
    """A PLY cloud, a DSM or a footprint file given as a tile: the one-line error says
    what the file is and where it goes, not laspy's 'Invalid file signature'."""
    p = tmp_path / "x.laz"
    p.write_bytes(head + bytes(300))
    with pytest.raises(FileFormatError, match=f"not a readable LAS/LAZ file: it is .*{says}"):
        read_las(p)


def test_feet_crs_read_in_metres(data):
    pc = read_points(data / "misc" / "autzen_trim.laz")
    assert pc.crs is not None
    assert pc.xy_unit == pytest.approx(0.3048)
    # ~1177 ft wide tile -> ~359 m
    width = np.ptp(pc.xyz[:, 0])
    assert 350 < width < 370


def test_crs_override_and_required(data):
    f = data / "delft" / "ahn3_cropped_1.laz"
    with pytest.raises(CRSError, match="--crs"):
        read_points(f, require_crs=True)
    pc = read_points(f, crs="EPSG:7415")
    assert pc.crs.is_compound and pc.xy_unit == 1.0


def test_write_keeps_attributes_and_is_atomic(data, tmp_path):
    tile = read_las(data / "misc" / "simple.laz")
    n = len(tile.data.points)
    out = tmp_path / "out.laz"
    write_las(out, tile, classification=np.full(n, 2))
    back = read_las(out)
    assert len(back.data.points) == n
    assert np.all(np.asarray(back.data.classification) == 2)
    assert np.allclose(back.data.x, tile.data.x)
    assert [p.name for p in tmp_path.iterdir()] == ["out.laz"]


def test_unknown_crs():
    from lidar2city.crs import parse_crs

    with pytest.raises(CRSError, match="unknown CRS"):
        parse_crs("EPSG:999999999")


@pytest.mark.parametrize("name", ["misc/simple.laz", "misc/autzen_trim.laz"])
def test_tiles_decoded_in_chunks_equal_the_whole_file(data, name):
    import laspy

    from lidar2city.io.las import POINT_ATTRIBUTES, _read_world

    las = laspy.read(data / name)
    scales = np.asarray(las.header.scales)
    expected = np.round(np.column_stack([las.x, las.y, las.z]) / scales) * scales
    for chunk in (97, 1_000_000):  # many chunks, a last short one / one chunk
        world, attrs = _read_world(data / name, chunk=chunk)
        assert np.array_equal(world, expected)
        names = [n for n in POINT_ATTRIBUTES if n in las.point_format.dimension_names]
        assert list(attrs) == names
        for n in names:
            assert attrs[n].dtype == np.asarray(las[n]).dtype
            assert np.array_equal(attrs[n], np.asarray(las[n]))


@pytest.mark.parametrize("case", ["true", "far", "above", "wide"])
def test_tile_steps_whatever_the_header_says(tmp_path, case):
    """read_tile's steps and base are the file's integer steps from their lowest,
    int32 unless the tile spans 2**31 steps, whether the header's lower corner is
    right, far off, above the points, or the points outgrow int32 after a chunk."""
    import struct

    import laspy

    from lidar2city.io.las import read_tile

    rng = np.random.default_rng(3)
    xyz = np.column_stack([85_000 + rng.uniform(0, 50, 500), 447_000 + rng.uniform(0, 40, 500),
                           rng.uniform(-5, 30, 500)])
    if case == "wide":  # 25 km in x at 0.01 mm: 2.5e9 steps, the far points after the first chunk
        xyz[400:, 0] += 25_000.0
    h = laspy.LasHeader(point_format=1, version="1.2")
    h.scales = np.array([1e-5, 1e-5, 1e-3]) if case == "wide" else np.array([1e-3] * 3)
    h.offsets = np.array([97_525.0 if case == "wide" else 85_000.0, 447_000.0, 0.0])
    las = laspy.LasData(h)
    las.x, las.y, las.z = xyz.T
    las.classification = rng.integers(1, 7, 500).astype(np.uint8)
    path = tmp_path / f"{case}.las"
    las.write(path)
    if case in ("far", "above"):  # min x and min y of the LAS 1.2 header (offsets 187, 203)
        shift = 1e12 if case == "far" else 7.5
        raw = bytearray(path.read_bytes())
        for at in (187, 203):
            v = struct.unpack_from("<d", raw, at)[0]
            struct.pack_into("<d", raw, at, v + shift)
        path.write_bytes(bytes(raw))
    back = laspy.read(path)
    steps = np.round(np.column_stack([back.x, back.y, back.z]) / back.header.scales).astype(np.int64)
    for chunk in (64, 1_000):
        tile = read_tile(path, chunk=chunk)
        assert np.array_equal(tile.base, steps.min(axis=0)) and tile.base.dtype == np.int64
        assert tile.steps.dtype == (np.int64 if case == "wide" else np.int32)
        assert np.array_equal(tile.steps.astype(np.int64) + tile.base, steps)
        assert np.array_equal(tile.attrs["classification"], np.asarray(back.classification))


def test_chunked_tile_read_reports_a_bad_file(tmp_path):
    from lidar2city.io.las import _read_world

    bad = tmp_path / "bad.laz"
    bad.write_bytes(b"LASF" + b"\0" * 100)
    with pytest.raises(FileFormatError):
        _read_world(bad)


def test_canonical_order_is_the_seven_key_lexsort():
    """The one-key sort of the tile reader gives np.lexsort's order, ties included."""
    from lidar2city.io.las import _canonical_order

    rng = np.random.default_rng(3)
    for dup in (False, True):
        n = 2000
        cols = [rng.integers(0, 4, n).astype(float) if dup else rng.normal(size=n) * 100
                for _ in range(3)]
        cols[0][:2] = [-0.0, 0.0]  # equal under comparison: the same rank
        attrs = [rng.integers(0, 3, n).astype(np.uint8), rng.integers(0, 9, n).astype(np.uint16)]
        want = np.lexsort(attrs[::-1] + cols[::-1])
        assert np.array_equal(_canonical_order(cols, attrs), want)


@pytest.mark.parametrize("late", [0, 20_000, 99_999])
def test_has_classes_finds_a_class_wherever_it_first_appears(tmp_path, late):
    """The class scan reads growing chunks: a class first met deep in the file (past the
    first small chunks) is found, and one that is absent is not."""
    from lidar2city.datamodel import PointCloud
    from lidar2city.io.las import TileReader, scan_tiles, write_points

    n = 100_000
    xyz = np.random.default_rng(0).uniform(0, 100, (n, 3))
    cls = np.full(n, 2, dtype=np.uint8)
    cls[late:] = 6
    out = tmp_path / "t.laz"
    write_points(out, PointCloud(xyz, attributes={"classification": cls}))
    reader = TileReader(scan_tiles([out], crs="EPSG:28992"))
    assert reader.has_classes([6])
    assert not reader.has_classes([17])


@pytest.mark.parametrize("dup", [False, True])
def test_points_of_tiles_sorted_on_integer_steps_as_on_coordinates(dup):
    """The tile reader sorts the points of same-resolution tiles on their integer
    steps: the same order (ties by attributes included) as the float lexsort."""
    from lidar2city.io.las import DecodedTile, _points_order

    rng = np.random.default_rng(5)
    parts = []
    for base in ([85_000_000, 447_000_000, -18_000], [85_200_000, 446_990_000, 0]):
        n = 1500
        steps = rng.integers(0, 4 if dup else 200_000, (n, 3)).astype(np.int32)
        attrs = {"classification": rng.integers(0, 3, n).astype(np.uint8),
                 "intensity": rng.integers(0, 9, n).astype(np.uint16)}
        parts.append(DecodedTile(steps, np.array(base, dtype=np.int64),
                                 np.full(3, 0.001), attrs))
    world = np.concatenate([p.world() for p in parts])
    attrs = [np.concatenate([p.attrs[k] for p in parts]) for k in ("classification", "intensity")]
    want = np.lexsort(attrs[::-1] + [world[:, 2], world[:, 1], world[:, 0]])
    order, cols = _points_order(parts, attrs)
    assert np.array_equal(order, want)
    for d in range(3):
        assert np.array_equal(cols(d, order), world[want, d])


@pytest.mark.parametrize("n", [0, 1, 500])
def test_a_spilled_tile_loads_back_the_same(n):
    """A decoded tile written to a scratch file (empty ones included) loads back equal."""
    from lidar2city.io.las import DecodedTile

    rng = np.random.default_rng(2)
    tile = DecodedTile(rng.integers(0, 10**6, (n, 3)).astype(np.int32),
                       np.array([85_000_000, 447_000_000, 0], dtype=np.int64), np.full(3, 0.001),
                       {"classification": rng.integers(0, 9, n).astype(np.uint8),
                        "intensity": rng.integers(0, 999, n).astype(np.uint16)})
    spilled = tile.spill()
    back = spilled.load()
    spilled.close()
    assert len(spilled) == n and np.array_equal(back.steps, tile.steps)
    assert back.steps.dtype == np.int32 and np.array_equal(back.world(), tile.world())
    assert all(np.array_equal(back.attrs[k], v) and back.attrs[k].dtype == v.dtype
               for k, v in tile.attrs.items())


def _with_count(tmp_path, name, delta):
    """A tile whose header's (legacy) point count is off by ``delta``."""
    import struct

    import laspy

    rng = np.random.default_rng(0)
    las = laspy.LasData(laspy.LasHeader(point_format=1, version="1.2"))
    xyz = rng.uniform(0, 50, (3000, 3))
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    p = tmp_path / name
    las.write(p)
    b = bytearray(p.read_bytes())
    struct.pack_into("<I", b, 107, struct.unpack_from("<I", b, 107)[0] + delta)
    p.write_bytes(bytes(b))
    return p


def test_a_wrong_header_point_count_is_found_when_the_tiles_are_scanned(tmp_path, caplog):
    """A LAZ whose header counts more points than it holds passed the scan and failed in
    every block that read it (reconstruct with footprints: a model of failed buildings,
    exit 0); it is now a one-line error before any work. An uncompressed tile holding
    more records than its header counts is read to the count, with a warning."""
    from lidar2city.errors import FileFormatError
    from lidar2city.io.las import scan_tiles

    bad = _with_count(tmp_path, "more.laz", 1000)
    with pytest.raises(FileFormatError, match="header counts 4,000 points but its compressed"):
        scan_tiles([bad])
    with pytest.raises(FileFormatError, match="header counts 4,000 points"):
        read_las(bad)
    good = _with_count(tmp_path, "ok.laz", 0)
    assert scan_tiles([good])[0].count == 3000
    less = _with_count(tmp_path, "less.las", -1000)
    with caplog.at_level("WARNING"):
        assert scan_tiles([less])[0].count == 2000
        assert len(read_las(less).data.points) == 2000
    assert "holds 3,000 point records, its header counts 2,000" in caplog.text
    # a second scan of tiles already checked (reconstruct taking the footprints' CRS for
    # tiles without one) decodes nothing: the lie is not looked for again
    assert scan_tiles([bad], check_count=False)[0].count == 4000


def test_a_large_scan_reads_chunk_tables_only(tmp_path):
    """Past EXACT_SCAN_TILES tiles the scan decodes nothing (50,000 tiles would take ~20
    min of decoding before any block runs): a count beyond a LAZ file's chunks is still
    an error, a count within its last chunk is left to the blocks that read the tile."""
    from lidar2city.errors import FileFormatError
    from lidar2city.io.las import EXACT_SCAN_TILES, scan_tiles

    good = [_with_count(tmp_path, f"ok{i}.laz", 0) for i in range(EXACT_SCAN_TILES)]
    within = _with_count(tmp_path, "within.laz", 1000)  # 4,000 counted, one chunk of 50,000
    beyond = _with_count(tmp_path, "beyond.laz", 57000)  # 60,000 counted
    assert scan_tiles(good + [within])[-1].count == 4000
    with pytest.raises(FileFormatError, match="chunk table holds at most 50,000"):
        scan_tiles(good + [beyond])
    with pytest.raises(FileFormatError, match="header counts 4,000 points"):
        scan_tiles(good[:3] + [within])
