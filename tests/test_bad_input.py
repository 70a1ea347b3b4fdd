"""Bad input: one clear message naming what is wrong, from the API and from the CLI."""

import numpy as np
import pytest
import trimesh
from helpers import assert_one_line_error, box_surface, icosphere, run_cli, write_mould

from hydrotact import HydrotactError
from hydrotact.field import make_laplace_problem
from hydrotact.mesh import Plane, make_box, make_tet_mesh, tetrahedralize, write_mesh

UNIT_TET = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float) * 1e-3


def _open_surface():
    surface = icosphere()
    return trimesh.Trimesh(surface.vertices, surface.faces[1:], process=False)


def _self_intersecting_surface():
    first = box_surface((4e-3, 4e-3, 4e-3))
    second = box_surface((4e-3, 4e-3, 4e-3))
    second.apply_translation([2e-3, 1e-3, 1e-3])
    return trimesh.util.concatenate([first, second])


def test_non_closed_surface(tmp_path):
    with pytest.raises(HydrotactError, match="not closed"):
        tetrahedralize(_open_surface(), 1e-3)


def test_self_intersecting_surface(tmp_path):
    with pytest.raises(HydrotactError, match="intersects itself"):
        tetrahedralize(_self_intersecting_surface(), 1e-3)


def test_clean_surfaces_are_not_reported_as_self_intersecting():
    from hydrotact.mesh import find_self_intersections, seed_surface

    for vertices, faces in (seed_surface("ellipsoid8"), (icosphere().vertices, icosphere().faces)):
        assert len(find_self_intersections(np.asarray(vertices), np.asarray(faces))) == 0


def test_zero_volume_tet(tmp_path):
    flat = UNIT_TET.copy()
    flat[3] = [0.3e-3, 0.3e-3, 0.0]
    with pytest.raises(HydrotactError, match="tet 0 is degenerate"):
        make_tet_mesh(flat, [[0, 1, 2, 3]])
    with pytest.raises(HydrotactError, match="repeats a vertex"):
        make_tet_mesh(UNIT_TET, [[0, 1, 2, 2]])


def test_inverted_tet(tmp_path):
    with pytest.raises(HydrotactError, match="tet 0 is inverted"):
        make_tet_mesh(UNIT_TET, [[0, 2, 1, 3]])


def test_no_core_faces(tmp_path):
    mesh = make_box((2e-3, 2e-3, 2e-3), 0.5e-3, bottom="free")
    with pytest.raises(HydrotactError, match="no core faces"):
        make_laplace_problem(mesh)
    with pytest.raises(HydrotactError, match="matches none"):
        tetrahedralize(box_surface(), 1e-3, core=Plane((0.0, 0.0, -1e-3)))
    path = tmp_path / "ball.stl"
    icosphere().export(path)
    assert_one_line_error(run_cli("field", path, "--core-plane", "-0.1"), "ball.stl", "no boundary face lies on the core")
    path = tmp_path / "allfree.vtu"
    write_mesh(mesh, path)
    assert_one_line_error(run_cli("field", path), "allfree.vtu", "no core faces")


def test_nan_coordinates(tmp_path):
    vertices = UNIT_TET.copy()
    vertices[2, 1] = np.nan
    with pytest.raises(HydrotactError, match="vertex 2 has a non-finite coordinate"):
        make_tet_mesh(vertices, [[0, 1, 2, 3]])
    surface = box_surface()
    surface_vertices = np.array(surface.vertices)
    surface_vertices[5, 0] = np.nan
    with pytest.raises(HydrotactError, match="vertex 5 has a non-finite coordinate"):
        tetrahedralize((surface_vertices, surface.faces), 1e-3)
    path = tmp_path / "nan.vtk"
    _write_raw_vtu(path, vertices, [[0, 1, 2, 3]])
    assert_one_line_error(run_cli("mesh", path), "nan.vtk", "non-finite")


@pytest.mark.parametrize("edge_length", [0.0, -1e-3, float("nan")])
def test_bad_edge_length(edge_length):
    with pytest.raises(HydrotactError, match="edge length must be a positive length"):
        tetrahedralize(box_surface(), edge_length)
    with pytest.raises(HydrotactError, match="edge length must be a positive length"):
        make_box((1e-3, 1e-3, 1e-3), edge_length)


def test_output_is_not_touched_on_error(tmp_path):
    """A failing run leaves an earlier good output file as it was, through the real
    entry point (a process of its own; the table below runs its cases in process, among
    them every error these tests' files once ran as processes: open, self-intersecting,
    degenerate and inverted inputs, bad edge lengths, unknown sensors)."""
    good = tmp_path / "mesh.vtu"
    assert run_cli("mesh", "pad5x5", "--edge-length", "2e-3", "-o", good).returncode == 0
    before = good.read_bytes()
    result = run_cli("mesh", "pad5x5", "--edge-length", "0", "-o", good)
    assert result.returncode == 2
    assert good.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.vtu"]


def test_a_refused_job_removes_the_folder_it_made_and_keeps_one_that_was_there(tmp_path):
    """train's model folder and design's .partial/: a refused run leaves nothing it
    made, and never removes a folder that was there (a killed run's state, earlier output)."""
    from hydrotact._files import removed_if_refused

    for existed in (False, True):
        folder = tmp_path / f"existed-{existed}"
        if existed:
            folder.mkdir()
            (folder / "checkpoint.npz").write_bytes(b"earlier")
        with pytest.raises(HydrotactError, match="refused"), removed_if_refused(folder):
            folder.mkdir(exist_ok=True)
            (folder / "weights.npz").write_bytes(b"half-written")
            raise HydrotactError("refused")
        assert folder.exists() == existed
        if existed:
            assert (folder / "checkpoint.npz").read_bytes() == b"earlier"
    with pytest.raises(KeyboardInterrupt), removed_if_refused(tmp_path / "killed"):  # not a refusal: kept to resume
        (tmp_path / "killed").mkdir()
        raise KeyboardInterrupt
    assert (tmp_path / "killed").is_dir()


def _write_raw_vtu(path, vertices, tets):
    """Write a mesh file without hydrotact's checks (to feed it bad meshes)."""
    import pyvista as pv

    tets = np.asarray(tets)
    cells = np.column_stack([np.full(len(tets), 4), tets]).reshape(-1)
    grid = pv.UnstructuredGrid(cells, np.full(len(tets), 10, dtype=np.uint8), np.asarray(vertices))
    grid.save(str(path), binary=False)


# --- the table: every command and file kind, through the command line -----------------
#
# Each case runs `hydrotact ARGS` in-process in a fresh folder (inputs in a shared,
# read-only one) and is one of three classes:
# - refused: exit 2, one line `hydrotact: error: ...` naming the file, field or row
#   (its fragments), no traceback, and no file written or changed anywhere (checksums
#   of the inputs and of the working folder, which may hold an earlier good output);
# - warned: exit 0, a `hydrotact: warning: ...` line with the figures (its fragments);
# - clear: exit 0 and no warning (inputs that look odd but are right).
# `{d}` in an argument is the inputs folder.

REFUSED, WARNED, CLEAR = "refused", "warned", "clear"
TRAJECTORY = "time,x,y,z\n" + "".join(f"{t / 10:g},0,0,{4.3e-3 - 0.6e-3 * min(t, 20 - t, 6) / 6:.6g}\n" for t in range(21))
EARLIER = b"an earlier good output\n"


def _write_parquet(path, columns, metadata):
    """A Parquet log as given (no hydrotact checks: to feed bad logs in)."""
    import json

    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({name: np.asarray(values) for name, values in columns.items()})
    if metadata is not None:
        table = table.replace_schema_metadata({b"hydrotact": json.dumps(metadata).encode()})
    pq.write_table(table, path)


def _variant(log, path, columns=None, metadata=None, drop=()):
    """`log` with some columns or metadata fields replaced, written to `path`."""
    new_columns = {name: values for name, values in log.columns.items() if name not in drop}
    new_columns.update(columns or {})
    new_metadata = {**log.metadata, **(metadata or {})}
    _write_parquet(path, new_columns, new_metadata)


def _json(path, document):
    import json

    path.write_text(document if isinstance(document, str) else json.dumps(document))


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """Every input file the table uses, good and bad, in one folder."""
    import json

    from sysid_synthetic import make_lumped_log

    from hydrotact.cli.simulate import run_simulate
    from hydrotact.data import read_log, write_log
    from hydrotact.sensors import load_sensor
    from hydrotact.visco import make_prony

    d = tmp_path_factory.mktemp("inputs")
    (d / "traj.csv").write_text(TRAJECTORY)
    soft = 2e5  # Pa: a soft skin, whose deepest press here stays inside the BMP388's range
    run_simulate("pad5x5", "cylinder:d=2mm", d / "traj.csv", d / "elastic.parquet", modulus=soft, num_rays=16, progress=False)
    run_simulate("pad5x5", "cylinder:d=2mm", d / "traj.csv", d / "baro.parquet", modulus=soft, num_rays=16, barometer=True, progress=False)
    elastic, baro = read_log(d / "elastic.parquet"), read_log(d / "baro.parquet")
    relative = make_prony(1.0, [0.5], [2.0])
    lumped = make_lumped_log(relative, [800.0, 1500.0], [1.5, 2.0], duration=30.0, rate_hz=50.0, seed=3, holds=(2.0, 6.0))
    write_log(d / "lumped.parquet", lumped)
    write_log(d / "lumped2.parquet", make_lumped_log(relative, [800.0, 1500.0], [1.5, 2.0], duration=30.0, rate_hz=50.0, seed=4, holds=(2.0, 6.0)))
    write_log(d / "elastic.csv", elastic)

    # logs that are wrong in one way each
    channels = baro.metadata["channels"]
    _variant(baro, d / "hpa.parquet", {name: baro.columns[name] / 100.0 for name in channels})
    _variant(baro, d / "x50.parquet", {name: baro.columns[name] * 50.0 for name in channels})
    _variant(baro, d / "ms.parquet", {"time": baro.columns["time"] * 1e3})
    clipped = np.minimum(baro.columns[channels[12]], np.quantile(baro.columns[channels[12]], 0.9))
    _variant(baro, d / "clipped.parquet", {channels[12]: np.where(clipped >= clipped.max(), 125000.0, clipped)})
    _variant(baro, d / "constant.parquet", {name: np.full(baro.num_samples, 101325.0) for name in channels})
    _variant(baro, d / "other_sensor.parquet", metadata={"sensor": "nosuch"})
    _variant(baro, d / "bad_probe.parquet", metadata={"probe": "cube:a=1"})
    _variant(elastic, d / "swapped.parquet", {channels[12]: elastic.columns[channels[7]], channels[7]: elastic.columns[channels[12]]})
    _variant(elastic, d / "negative.parquet", {channels[12]: -elastic.columns[channels[12]] - 1.0})
    _write_parquet(d / "no_metadata.parquet", elastic.columns, None)
    _variant(elastic, d / "nan.parquet", {channels[0]: np.where(np.arange(elastic.num_samples) == 4, np.nan, elastic.columns[channels[0]])})
    _variant(elastic, d / "backwards.parquet", {"time": elastic.columns["time"][::-1].copy()})
    _variant(elastic, d / "wrong_count.parquet", metadata={"channels": channels[:24]}, drop=channels[24:])
    _variant(elastic, d / "unknown_column.parquet", {"colour": np.zeros(elastic.num_samples)})
    _variant(elastic, d / "bad_format.parquet", metadata={"format": "barometer"})
    _variant(elastic, d / "bad_reference.parquet", metadata={"pressure": "gauge"})
    _variant(read_log(d / "lumped2.parquet"), d / "lumped_other_sensor.parquet", metadata={"sensor": "other"})
    (d / "garbage.parquet").write_bytes(bytes(range(256)) * 8)
    (d / "garbage.csv").write_bytes(bytes(range(128, 256)) * 20)
    _json(d / "garbage.json", elastic.metadata)
    (d / "semicolon.csv").write_text((d / "elastic.csv").read_text().replace(",", ";"))
    _json(d / "semicolon.json", elastic.metadata)
    (d / "short.csv").write_text("time,b00\n0,1\n")
    _json(d / "short.json", elastic.metadata)
    (d / "log.txt").write_text("time\n0\n")

    # trajectories
    rows = TRAJECTORY.splitlines()
    for name, text in {
        "mm": "time,x,y,z\n0,0,0,4.3\n1,0,0,3.6\n2,0,0,4.3\n",
        "below": "time,x,y,z\n0,0,0,-0.05\n1,0,0,-0.05\n",
        "far": "time,x,y,z\n0,0.05,0,0.0043\n1,0.05,0,0.0036\n",
        "dup": "time,x,y,z,x\n0,0,0,0.0043,1\n",
        "rX": "time,x,y,z,rX,ry,rz\n0,0,0,0.0043,0,0,0\n",
        "force_col": "time,x,y,z,fz\n0,0,0,0.0043,1\n",
        "two_rot": "time,x,y,z,rx,ry\n0,0,0,0.0043,0,0\n",
        "no_z": "time,x,y\n0,0,0\n",
        "semicolon": "time;x;y;z\n0;0;0;0.0043\n",
        "tab": "time\tx\ty\tz\n0\t0\t0\t0.0043\n",
        "decimal_comma": "time,x,y,z\n0,5,0,0,0,0043\n",
        "text_cell": "time,x,y,z\n0,0,0,high\n",
        "nan_cell": "time,x,y,z\n0,0,0,nan\n",
        "inf_cell": "time,x,y,z\n0,0,0,inf\n",
        "back": "time,x,y,z\n0,0,0,0.0043\n1,0,0,0.0043\n0.5,0,0,0.0043\n",
        "repeat": "time,x,y,z\n0,0,0,0.0043\n0,0,0,0.0043\n",
        "ragged": "time,x,y,z\n0,0,0\n",
        "empty": "",
        "header_only": "time,x,y,z\n",
        "hover": "time,x,y,z\n0,0,0,0.006\n1,0,0,0.0055\n",
    }.items():
        (d / f"traj_{name}.csv").write_text(text)
    (d / "traj_binary.csv").write_bytes(bytes(range(128, 256)) * 20)
    (d / "traj_crlf_bom.csv").write_bytes(("\ufeff" + "\r\n".join(rows) + "\r\n").encode("utf-8"))

    # materials
    good_material = {"format": "hydrotact.material", "version": 1, "long_term_modulus_Pa": {"value": 6e5}, "prony_terms": [{"modulus_Pa": {"value": 2e5}, "tau_s": {"value": 1.0}}],
        "provenance": {"generator": "test", "created": "2026-11-25T00:00:00Z", "method": "manual"}}
    _json(d / "material.json", good_material)
    _json(d / "material_negative.json", {**good_material, "long_term_modulus_Pa": {"value": -6e5}})
    _json(d / "material_tau0.json", {**good_material, "prony_terms": [{"modulus_Pa": {"value": 2e5}, "tau_s": {"value": 0.0}}]})
    _json(d / "material_format.json", {**good_material, "format": "material"})
    _json(d / "material_missing.json", {k: v for k, v in good_material.items() if k != "prony_terms"})
    _json(d / "material_relative.json", {**good_material, "modulus_scale": "relative", "long_term_modulus_Pa": {"value": 1.0}})
    _json(d / "material_malformed.json", '{"format": "hydrotact.material", ')
    _json(d / "material_list.json", "[1, 2]")

    # sensor specs
    pad = load_sensor("pad5x5").to_json()

    def sensor(name, change):
        document = json.loads(json.dumps(pad))
        change(document)
        _json(d / f"sensor_{name}.json", document)

    sensor("copy", lambda s: s.update(name="pad5x5-copy"))  # another cast of the same design
    _variant(elastic, d / "elastic_copy.parquet", {name: elastic.columns[name] * 1.01 for name in channels}, metadata={"sensor": str(d / "sensor_copy.json")})
    sensor("time_taxel", lambda s: s["taxels"][3].update(name="time"))
    sensor("axis_out", lambda s: s["taxels"][3].update(axis=[0, 0, -1]))
    sensor("axis_zero", lambda s: s["taxels"][3].update(axis=[0, 0, 0]))
    sensor("outside", lambda s: s["taxels"][3].update(position=[0.0, 0.0, 0.01]))
    sensor("dup_name", lambda s: s["taxels"][3].update(name=s["taxels"][2]["name"]))
    sensor("unknown_part", lambda s: s.update(part="BMP999"))
    sensor("unknown_seed", lambda s: s["geometry"].update(seed="pad6x6"))
    sensor("no_taxels", lambda s: s.update(taxels=[]))
    sensor("bad_units", lambda s: s["units"].update(length="furlong"))
    sensor("negative_radius", lambda s: s["taxels"][0]["receptive_field"].update(radius=-1.0))
    sensor("unknown_field", lambda s: s.update(colour="red"))
    sensor("missing_surface", lambda s: s.update(geometry={"kind": "surface", "path": "nowhere.stl", "core_plane_z": 0.0, "edge_length": 1.0}))
    _json(d / "sensor_malformed.json", '{"name": "x",')

    # surfaces and tet meshes
    _open_surface().export(d / "open.stl")
    _self_intersecting_surface().export(d / "crossing.stl")
    box_mm = box_surface((13.2, 13.2, 4.0))  # a pad in mm, read as metres: a 13 m elastomer
    box_mm.export(d / "pad_in_mm.stl")
    nan_surface = box_surface()
    nan_vertices = np.array(nan_surface.vertices)
    nan_vertices[2, 0] = np.nan
    trimesh.Trimesh(nan_vertices, nan_surface.faces, process=False).export(d / "nan.obj")
    flat = box_surface()
    degenerate_faces = np.vstack([flat.faces, [[0, 0, 1]]])
    trimesh.Trimesh(flat.vertices, degenerate_faces, process=False).export(d / "zero_area.obj")
    two = trimesh.util.concatenate([icosphere(3e-3), icosphere(3e-3, center=(2.1e-3, 0.3e-3, 0.2e-3))])
    two.export(d / "two_shells.stl")
    (d / "garbage.stl").write_bytes(bytes(range(256)) * 4)
    write_mould(d / "tray.stl", ((0, 0, 0), (10, 8, 6)), [((2, 2, 2), (8, 6, 6.5))])  # mm
    write_mould(d / "two_trays.stl", ((0, 0, 0), (20, 8, 6)), [((2, 2, 2), (8, 6, 6.5)), ((12, 2, 2), (18, 6, 6.5))])
    (d / "surface.xyz").write_text("0 0 0\n")
    flat_tet = UNIT_TET.copy()
    flat_tet[3] = [0.3e-3, 0.3e-3, 0.0]
    _write_raw_vtu(d / "flat.vtu", flat_tet, [[0, 1, 2, 3]])
    _write_raw_vtu(d / "inverted.vtk", UNIT_TET, [[0, 2, 1, 3]])
    write_mesh(make_box((2e-3, 2e-3, 2e-3), 0.5e-3), d / "box.vtu")

    # column mappings (for lumped.csv, a CSV of the user's own layout)
    (d / "rig.csv").write_text("t,p0,p1,z\n" + "".join(f"{k * 0.02:.2f},{101325 + 50 * (k % 7)},{101300 + 30 * (k % 5)},{0.0001 * (k % 9)}\n" for k in range(200)))
    mapping = {"format": "hydrotact.column_mapping", "version": 1, "pressure": "absolute", "rate_hz": 50.0, "time": {"column": "t", "unit": "s"},
        "channels": [{"column": "p0", "unit": "Pa"}, {"column": "p1", "unit": "Pa"}], "columns": {"indentation": {"column": "z", "unit": "m"}}}
    _json(d / "map.json", mapping)
    _json(d / "map_scale0.json", {**mapping, "columns": {"indentation": {"column": "z", "unit": "m", "scale": 0}}})
    _json(d / "map_kpa.json", {**mapping, "channels": [{"column": "p0", "unit": "kPa"}, {"column": "p1", "unit": "kPa"}]})
    _json(d / "map_hpa_as_pa.json", mapping)
    (d / "rig_hpa.csv").write_text("t,p0,p1,z\n" + "".join(f"{k * 0.02:.2f},{1013.25 + 0.5 * (k % 7)},{1013.0 + 0.3 * (k % 5)},{0.0001 * (k % 9)}\n" for k in range(200)))
    _json(d / "map_ms.json", {**mapping, "time": {"column": "t", "unit": "ms"}})
    _json(d / "map_missing_column.json", {**mapping, "channels": [{"column": "p9", "unit": "Pa"}]})
    _json(d / "map_unit.json", {**mapping, "time": {"column": "t", "unit": "fortnight"}})
    _json(d / "map_kind.json", {**mapping, "channels": [{"column": "p0", "unit": "mm"}]})
    _json(d / "map_malformed.json", '{"format": ')
    _json(d / "map_semicolon.json", {**mapping, "csv": {"delimiter": ";"}})
    (d / "rig_semicolon.csv").write_text((d / "rig.csv").read_text().replace(",", ";"))
    (d / "rig_decimal_comma.csv").write_text("t;p0;p1;z\n" + "".join(f"{k * 0.02:.2f};{101325 + 50 * (k % 7)};{101300 + 30 * (k % 5)};{0.0001 * (k % 9)}\n" for k in range(200)).replace(".", ","))
    (d / "afile").write_text("not a folder\n")
    _write_models(d, baro)
    _write_datasets(d)
    return d


def _write_datasets(d):
    """The recorded two-event sphere8 dataset (tests/data/tiny_dataset), and copies of
    it damaged in one way each."""
    import json
    import shutil
    from pathlib import Path

    recorded = Path(__file__).parent / "data" / "tiny_dataset"
    for name in ("dataset", "ds_split", "ds_no_shard", "ds_bad_sha", "ds_unfinished", "ds_garbage"):
        shutil.copytree(recorded, d / name)

    def edit(name, change):
        document = json.loads((d / name / "manifest.json").read_text())
        change(document)
        _json(d / name / "manifest.json", document)

    edit("ds_split", lambda m: m["split"].update(train=[[0, 5000]]))  # a manifest edited by hand
    edit("ds_bad_sha", lambda m: m["shards"][0].update(sha256="0" * 64))  # a shard changed since
    (d / "ds_no_shard" / "shard-00000.parquet").unlink()
    (d / "ds_unfinished" / "manifest.json").unlink()  # a run killed before its end
    (d / "ds_unfinished" / ".partial").mkdir()
    _json(d / "ds_unfinished" / ".partial" / "state.json", {"request_digest": "another run's"})
    (d / "ds_garbage" / "manifest.json").write_text('{"format": ')


def _write_models(d, baro):
    """An (untrained: the table checks what is read, not what is learnt) estimator of
    pad5x5, and copies of it damaged in one way each; baro.parquet without its labels."""
    import json
    import shutil

    import jax

    from hydrotact.models import TrainConfig, TrainedEstimator, init_estimator, make_estimator_spec, save_estimator
    from hydrotact.models._sequences import Normaliser
    from hydrotact.sensors import load_sensor

    sensor = load_sensor("pad5x5")
    spec = make_estimator_spec(sensor, hidden=(8, 8))
    channels = tuple(sensor.taxel_names)
    normaliser = Normaliser(np.full(len(channels), 101325.0), np.full(len(channels), 500.0))
    trained = TrainedEstimator(spec, init_estimator(spec, jax.random.PRNGKey(0)), normaliser, channels, TrainConfig(hidden=(8, 8)), [{"epoch": 0}], 0, "a test's stand-in")
    save_estimator(trained, d / "model", "pad5x5")
    document = json.loads((d / "model" / "model.json").read_text())

    def damaged(name, change):
        shutil.copytree(d / "model", d / f"model_{name}")
        copy = json.loads(json.dumps(document))
        change(copy)
        _json(d / f"model_{name}" / "model.json", copy)

    damaged("channels", lambda m: m.update(channels=m["channels"][:8]))  # a sphere8 model's eight names pasted in
    damaged("no_spec", lambda m: m.pop("spec"))
    damaged("architecture", lambda m: m["spec"].update(architecture="lstm"))
    damaged("std_zero", lambda m: m["normaliser"].update(std_Pa=[0.0] * len(channels)))
    damaged("best_epoch", lambda m: m.update(best_epoch=7))
    damaged("format", lambda m: m.update(format="hydrotact.model"))
    _json(d / "model_list.json", "[]")
    shutil.copytree(d / "model", d / "model_not_json")
    (d / "model_not_json" / "model.json").write_text('{"format": "hydrotact.estimator",')
    shutil.copytree(d / "model", d / "model_no_weights")
    (d / "model_no_weights" / "weights.npz").unlink()
    shutil.copytree(d / "model", d / "model_nan")
    with np.load(d / "model" / "weights.npz") as saved:
        weights = {name: saved[name].copy() for name in saved.files}
    weights["w0"].flat[0] = np.nan
    np.savez(d / "model_nan" / "weights.npz", **weights)
    labels = [name for name in ("fx", "fy", "fz", "fn", "contact", "theta", "phi") if name in baro.columns]
    _variant(baro, d / "baro_unlabelled.parquet", drop=labels)


SIM = "simulate --sensor pad5x5 --probe cylinder:d=2mm --rays 8"
SIM_OK = f"{SIM} --trajectory {{d}}/traj.csv"
FIT = "fit {d}/elastic.parquet"
CONTACT = "contact --sensor pad5x5 --probe sphere:r=3mm"

CASES = [
    # the command line itself
    ("no-command", "", REFUSED, ["required: COMMAND", "hydrotact --help"]),
    ("unknown-command", "bogus", REFUSED, ["invalid choice: 'bogus'"]),
    ("unknown-option", "mesh pad5x5 --colour red", REFUSED, ["unrecognized arguments: --colour red"]),
    # mesh
    ("mesh-no-source", "mesh", REFUSED, ["give a sensor or surface file to mesh, or --mould FILE"]),
    ("mesh-unknown-sensor", "mesh sphere9", REFUSED, ["sphere9", "neither a built-in sensor"]),
    ("mesh-missing-file", "mesh {d}/nowhere.stl", REFUSED, ["nowhere.stl", "no such file"]),
    ("mesh-unknown-suffix", "mesh {d}/surface.xyz", REFUSED, ["surface.xyz", "unknown file type '.xyz'"]),
    ("mesh-edge-text", "mesh pad5x5 --edge-length abc", REFUSED, ["--edge-length", "not a number: 'abc'"]),
    ("mesh-edge-zero", "mesh pad5x5 --edge-length 0", REFUSED, ["edge length must be a positive length"]),
    ("mesh-edge-negative", "mesh pad5x5 --edge-length -1e-3", REFUSED, ["edge length must be a positive length"]),
    ("mesh-edge-nan", "mesh pad5x5 --edge-length nan", REFUSED, ["edge length must be a positive length"]),
    ("mesh-edge-tiny", "mesh pad5x5 --edge-length 1e-9", REFUSED, ["pad5x5", "would make about 4.2e+21 tets", "at least 8.4e-05 m"]),
    ("mesh-edge-tiny-curved", "mesh sphere8 --edge-length 1e-9", REFUSED, ["sphere8", "tets of a surface 32 mm across"]),
    ("mesh-edge-in-um", "mesh pad5x5 --edge-length 10 --units um", REFUSED, ["pad5x5", "edge length 1e-05 m would make"]),
    ("mesh-units-unknown", "mesh pad5x5 --units furlong", REFUSED, ["--units", "invalid choice: 'furlong'"]),
    ("mesh-out-suffix", "mesh pad5x5 -o mesh.stl", REFUSED, ["mesh.stl", "*.vtu or *.vtk"]),
    ("mesh-out-is-folder", "mesh pad5x5 -o afolder.vtu", REFUSED, ["afolder.vtu", "is a folder, not a file"]),
    ("mesh-out-under-file", "mesh pad5x5 -o {d}/afile/mesh.vtu", REFUSED, ["afile is a file, not a folder"]),
    ("mesh-out-unwritable", "mesh pad5x5 -o /proc/mesh.vtu", REFUSED, ["/proc/mesh.vtu", "cannot write in /proc/"]),
    ("mesh-vtk-suffix", "mesh pad5x5 --vtk mesh.vtu", REFUSED, ["mesh.vtu", "*.vtk"]),
    ("mesh-png-suffix", "mesh pad5x5 --png mesh.jpg", REFUSED, ["mesh.jpg", "*.png"]),
    ("mesh-earlier-output-kept", "mesh pad5x5 --edge-length 0 -o earlier.vtu", REFUSED, ["edge length must be a positive length"]),
    ("surface-open", "mesh {d}/open.stl", REFUSED, ["open.stl", "not closed"]),
    ("surface-self-intersecting", "mesh {d}/crossing.stl", REFUSED, ["crossing.stl", "intersects itself"]),
    ("surface-two-shells", "mesh {d}/two_shells.stl", REFUSED, ["two_shells.stl", "intersects itself"]),
    ("surface-nan", "mesh {d}/nan.obj", REFUSED, ["nan.obj", "vertex 2 has a non-finite coordinate"]),
    ("surface-zero-area", "mesh {d}/zero_area.obj", REFUSED, ["zero_area.obj", "zero area"]),
    ("surface-in-mm", "mesh {d}/pad_in_mm.stl", REFUSED, ["pad_in_mm.stl", "in mm? (--units mm)"]),
    ("surface-garbage", "mesh {d}/garbage.stl", REFUSED, ["garbage.stl"]),
    ("mould-open", "mesh --mould {d}/open.stl", REFUSED, ["open.stl", "the mould is not closed", "edges do not belong to exactly two triangles"]),
    ("mould-convex", "mesh --mould {d}/pad_in_mm.stl --units mm", REFUSED, ["pad_in_mm.stl", "has no cavity (it is convex)"]),
    ("mould-two-cavities", "mesh --mould {d}/two_trays.stl --units mm", REFUSED, ["two_trays.stl", "the cavity is not one piece", "(96, 96 mm³)"]),
    ("mould-in-mm-read-as-m", "mesh --mould {d}/tray.stl", REFUSED, ["tray.stl", "in mm? (--units mm)"]),
    ("mould-missing", "mesh --mould {d}/nowhere_mould.stl --units mm", REFUSED, ["nowhere_mould.stl", "no such file"]),
    ("mould-garbage", "mesh --mould {d}/garbage.stl --units mm", REFUSED, ["garbage.stl"]),
    ("mould-and-sensor", "mesh pad5x5 --mould {d}/tray.stl", REFUSED, ["not both"]),
    ("mould-board-unknown", "mesh --mould {d}/tray.stl --units mm --board up", REFUSED, ["--board", "invalid choice: 'up'"]),
    ("mould-board-without-mould", "mesh pad5x5 --board ymax", REFUSED, ["--board", "applies to --mould"]),
    ("mould-second-part-missing", "mesh --mould {d}/tray.stl --mould {d}/nowhere_lid.stl --units mm", REFUSED, ["nowhere_lid.stl", "no such file"]),
    ("tet-degenerate", "field {d}/flat.vtu", REFUSED, ["flat.vtu", "tet 0 is degenerate"]),
    ("tet-inverted", "field {d}/inverted.vtk", REFUSED, ["inverted.vtk", "tet 0 is inverted"]),
    ("tet-mesh-edge-length", "field {d}/box.vtu --edge-length 1e-3", REFUSED, ["box.vtu", "--edge-length applies to sensors and surfaces"]),
    # field
    ("field-modulus-negative", "field pad5x5 --modulus -1e5", REFUSED, ["modulus must be a positive"]),
    ("field-modulus-zero", "field pad5x5 --modulus 0", REFUSED, ["modulus must be a positive"]),
    ("field-modulus-inf", "field pad5x5 --modulus inf", REFUSED, ["modulus must be a positive"]),
    ("field-modulus-text", "field pad5x5 --modulus soft", REFUSED, ["field:", "--modulus", "not a number: 'soft'"]),
    ("field-modulus-missing", "field pad5x5 --modulus", REFUSED, ["--modulus", "expected one argument"]),
    ("field-kind", "field pad5x5 --kind elastic", REFUSED, ["--kind", "invalid choice: 'elastic'"]),
    ("field-modulus-in-kpa", "field pad5x5 --modulus 100 --json", WARNED, ["--modulus", "100 Pa is outside the moduli of elastomer skins", "kPa"]),
    ("field-out-suffix", "field pad5x5 -o field.png", REFUSED, ["field.png", "*.vtu or *.vtk"]),
    ("field-png-unwritable", "field pad5x5 --png /proc/f.png", REFUSED, ["/proc/f.png", "cannot write"]),
    # contact
    ("contact-no-probe", "contact --sensor pad5x5 --at 0,0,0.4mm", REFUSED, ["contact:", "--probe"]),
    ("contact-two-sources", "contact --sensor pad5x5 --mesh {d}/box.vtu --probe plane --at 0,0,0.1mm", REFUSED, ["not allowed with argument"]),
    ("contact-unknown-sensor", "contact --sensor pad6x6 --probe plane --at 0,0,0.1mm", REFUSED, ["--sensor", "invalid choice: 'pad6x6'"]),
    ("contact-unknown-probe", "contact --sensor pad5x5 --probe cube:a=1mm --at 0,0,0.4mm", REFUSED, ["--probe", "unknown probe 'cube:a=1mm'"]),
    ("contact-probe-negative", "contact --sensor pad5x5 --probe sphere:r=-3mm --at 0,0,0.4mm", REFUSED, ["--probe", "r"]),
    ("contact-probe-no-unit", "contact --sensor pad5x5 --probe sphere:r=3 --at 0,0,0.4mm", REFUSED, ["--probe", "3 m"]),
    ("contact-at-two", f"{CONTACT} --at 0,0", REFUSED, ["--at", "expected X,Y,DEPTH"]),
    ("contact-at-text", f"{CONTACT} --at 0,0,deep", REFUSED, ["--at", "cannot read 'deep' as a length"]),
    ("contact-at-negative-depth", f"{CONTACT} --at 0,0,-1mm", REFUSED, ["--at", "the depth must be >= 0"]),
    ("contact-beyond-thickness", f"{CONTACT} --at 0,0,10mm", REFUSED, ["--at", "depth 10 mm reaches the sensor's base", "4 mm above it"]),
    ("contact-off-sensor", f"{CONTACT} --at 50mm,0,0.4mm", REFUSED, ["--at", "no part of the sensor lies under x = 0.05 m"]),
    ("contact-modulus-negative", f"{CONTACT} --at 0,0,0.4mm --modulus -1e5", REFUSED, ["modulus must be a positive"]),
    ("contact-png-suffix", f"{CONTACT} --at 0,0,0.4mm --png c.jpg", REFUSED, ["c.jpg", "*.png"]),
    ("contact-negative-x", f"{CONTACT} --at -2.2mm,0,0.4mm --json", CLEAR, []),
    # simulate: options
    ("sim-no-trajectory", SIM + " -o log.parquet", REFUSED, ["simulate:", "--trajectory"]),
    ("sim-missing-trajectory", SIM + " --trajectory {d}/nowhere.csv -o log.parquet", REFUSED, ["nowhere.csv", "no such trajectory file"]),
    ("sim-out-suffix", SIM_OK + " -o log.csv", REFUSED, ["log.csv", "*.parquet"]),
    ("sim-out-is-folder", SIM_OK + " -o afolder.parquet", REFUSED, ["afolder.parquet", "is a folder, not a file"]),
    ("sim-out-unwritable", SIM_OK + " -o /proc/log.parquet", REFUSED, ["/proc/log.parquet", "cannot write in /proc/"]),
    ("sim-out-under-file", SIM_OK + " -o {d}/afile/log.parquet", REFUSED, ["afile is a file, not a folder"]),
    ("sim-png-suffix", SIM_OK + " -o log.parquet --png log.svg", REFUSED, ["log.svg", "*.png"]),
    ("sim-noise-without-barometer", SIM_OK + " -o log.parquet --noise 0.1", REFUSED, ["--noise", "add --barometer"]),
    ("sim-gain-spread-huge", SIM_OK + " -o log.parquet --barometer --gain-spread 5", REFUSED, ["--gain-spread", "500%", "at most 0.25"]),
    ("sim-gain-spread-negative", SIM_OK + " -o log.parquet --barometer --gain-spread -0.1", REFUSED, ["--gain-spread", "non-negative"]),
    ("sim-offset-spread-nan", SIM_OK + " -o log.parquet --barometer --offset-spread nan", REFUSED, ["--offset-spread", "non-negative"]),
    ("sim-noise-negative", SIM_OK + " -o log.parquet --barometer --noise -1", REFUSED, ["--noise", "non-negative"]),
    ("sim-rays-zero", SIM_OK + " -o log.parquet --rays 0", REFUSED, ["--rays", "positive whole number"]),
    ("sim-rays-text", SIM_OK + " -o log.parquet --rays many", REFUSED, ["--rays", "invalid int value: 'many'"]),
    ("sim-seed-text", SIM_OK + " -o log.parquet --seed x", REFUSED, ["--seed", "invalid int value"]),
    ("sim-modulus-negative", SIM_OK + " -o log.parquet --modulus -1e6", REFUSED, ["--modulus", "positive"]),
    ("sim-field-unknown", SIM_OK + " -o log.parquet --field heat", REFUSED, ["--field", "invalid choice: 'heat'"]),
    ("sim-units-unknown", SIM_OK + " -o log.parquet --units inch", REFUSED, ["--units", "invalid choice: 'inch'"]),
    ("sim-unknown-sensor", "simulate --sensor nosuch --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED, ["nosuch", "neither a built-in sensor"]),
    ("sim-unknown-probe", "simulate --sensor pad5x5 --probe wedge --trajectory {d}/traj.csv -o log.parquet", REFUSED, ["--probe", "unknown probe 'wedge'"]),
    ("sim-earlier-output-kept", SIM + " --trajectory {d}/traj_mm.csv -o earlier.parquet", REFUSED, ["traj_mm.csv", "no pose comes near"]),
    # simulate: materials
    ("material-missing", SIM_OK + " -o log.parquet --material {d}/nowhere.json", REFUSED, ["nowhere.json"]),
    ("material-malformed", SIM_OK + " -o log.parquet --material {d}/material_malformed.json", REFUSED, ["material_malformed.json", "not valid JSON"]),
    ("material-list", SIM_OK + " -o log.parquet --material {d}/material_list.json", REFUSED, ["material_list.json", "must be an object"]),
    ("material-negative", SIM_OK + " -o log.parquet --material {d}/material_negative.json", REFUSED, ["material_negative.json", "long_term_modulus_Pa"]),
    ("material-tau-zero", SIM_OK + " -o log.parquet --material {d}/material_tau0.json", REFUSED, ["material_tau0.json", "tau_s"]),
    ("material-format", SIM_OK + " -o log.parquet --material {d}/material_format.json", REFUSED, ["material_format.json", "format"]),
    ("material-no-terms", SIM_OK + " -o log.parquet --material {d}/material_missing.json", REFUSED, ["material_missing.json", "prony_terms"]),
    ("material-relative", SIM_OK + " -o log.parquet --material {d}/material_relative.json", REFUSED, ["material_relative.json", "relative"]),
    # simulate: sensor specs
    ("sensor-time-taxel", "simulate --sensor {d}/sensor_time_taxel.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_time_taxel.json", "taxels[3].name", "'time' is a reserved log column"]),
    ("sensor-axis-out", "simulate --sensor {d}/sensor_axis_out.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_axis_out.json", "taxels[3].axis", "does not reach the skin"]),
    ("sensor-axis-zero", "simulate --sensor {d}/sensor_axis_zero.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_axis_zero.json", "taxels[3].axis", "must not be zero"]),
    ("sensor-port-outside", "simulate --sensor {d}/sensor_outside.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_outside.json", "taxels[3].position", "outside the pad5x5 elastomer"]),
    ("sensor-duplicate-name", "simulate --sensor {d}/sensor_dup_name.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_dup_name.json", "taxels[3].name", "already the name of taxels[2]"]),
    ("sensor-unknown-part", "simulate --sensor {d}/sensor_unknown_part.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_unknown_part.json", "part", "BMP999"]),
    ("sensor-unknown-seed", "simulate --sensor {d}/sensor_unknown_seed.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_unknown_seed.json", "geometry", "pad6x6"]),
    ("sensor-no-taxels", "simulate --sensor {d}/sensor_no_taxels.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_no_taxels.json", "taxels"]),
    ("sensor-bad-units", "simulate --sensor {d}/sensor_bad_units.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_bad_units.json", "units.length", "furlong"]),
    ("sensor-negative-radius", "simulate --sensor {d}/sensor_negative_radius.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_negative_radius.json", "taxels[0].receptive_field"]),
    ("sensor-unknown-field", "simulate --sensor {d}/sensor_unknown_field.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_unknown_field.json", "colour"]),
    ("sensor-missing-surface", "simulate --sensor {d}/sensor_missing_surface.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_missing_surface.json", "nowhere.stl"]),
    ("sensor-malformed", "simulate --sensor {d}/sensor_malformed.json --probe plane --trajectory {d}/traj.csv -o log.parquet", REFUSED,
        ["sensor_malformed.json", "not valid JSON"]),
    # simulate: trajectories
    ("traj-in-mm", SIM + " --trajectory {d}/traj_mm.csv -o log.parquet", REFUSED, ["traj_mm.csv", "no pose comes near the sensor", "in mm? (--units mm)"]),
    ("traj-below-board", SIM + " --trajectory {d}/traj_below.csv -o log.parquet", REFUSED, ["traj_below.csv", "no pose comes near", "below the sensor's base"]),
    ("traj-beside", SIM + " --trajectory {d}/traj_far.csv -o log.parquet", REFUSED, ["traj_far.csv", "no pose comes near", "closest at row 2"]),
    ("traj-duplicate-column", SIM + " --trajectory {d}/traj_dup.csv -o log.parquet", REFUSED, ["traj_dup.csv", "column 'x' appears twice"]),
    ("traj-unknown-column", SIM + " --trajectory {d}/traj_rX.csv -o log.parquet", REFUSED, ["traj_rX.csv", "unknown column 'rX'", "did you mean 'rx'"]),
    ("traj-force-column", SIM + " --trajectory {d}/traj_force_col.csv -o log.parquet", REFUSED, ["traj_force_col.csv", "unknown column 'fz'"]),
    ("traj-two-rotations", SIM + " --trajectory {d}/traj_two_rot.csv -o log.parquet", REFUSED, ["traj_two_rot.csv", "give all of rx, ry, rz or none"]),
    ("traj-no-z", SIM + " --trajectory {d}/traj_no_z.csv -o log.parquet", REFUSED, ["traj_no_z.csv", "missing column(s) z"]),
    ("traj-semicolon", SIM + " --trajectory {d}/traj_semicolon.csv -o log.parquet", REFUSED, ["traj_semicolon.csv", "separates fields by ';'"]),
    ("traj-tab", SIM + " --trajectory {d}/traj_tab.csv -o log.parquet", REFUSED, ["traj_tab.csv", "separates fields by '\\t'"]),
    ("traj-decimal-comma", SIM + " --trajectory {d}/traj_decimal_comma.csv -o log.parquet", REFUSED, ["traj_decimal_comma.csv", "row 1", "decimal commas?"]),
    ("traj-text-cell", SIM + " --trajectory {d}/traj_text_cell.csv -o log.parquet", REFUSED, ["traj_text_cell.csv", "row 1, column z", "not a number: 'high'"]),
    ("traj-nan-cell", SIM + " --trajectory {d}/traj_nan_cell.csv -o log.parquet", REFUSED, ["traj_nan_cell.csv", "row 1, column z", "not a finite number"]),
    ("traj-inf-cell", SIM + " --trajectory {d}/traj_inf_cell.csv -o log.parquet", REFUSED, ["traj_inf_cell.csv", "row 1, column z", "not a finite number"]),
    ("traj-time-back", SIM + " --trajectory {d}/traj_back.csv -o log.parquet", REFUSED, ["traj_back.csv", "row 3, column time", "does not increase"]),
    ("traj-time-repeats", SIM + " --trajectory {d}/traj_repeat.csv -o log.parquet", REFUSED, ["traj_repeat.csv", "row 2, column time", "does not increase"]),
    ("traj-ragged", SIM + " --trajectory {d}/traj_ragged.csv -o log.parquet", REFUSED, ["traj_ragged.csv", "row 1: 3 fields, expected 4"]),
    ("traj-empty", SIM + " --trajectory {d}/traj_empty.csv -o log.parquet", REFUSED, ["traj_empty.csv", "missing column(s)"]),
    ("traj-header-only", SIM + " --trajectory {d}/traj_header_only.csv -o log.parquet", REFUSED, ["traj_header_only.csv", "at least one sample"]),
    ("traj-binary", SIM + " --trajectory {d}/traj_binary.csv -o log.parquet", REFUSED, ["traj_binary.csv", "not a CSV text file"]),
    ("traj-never-touches", SIM + " --trajectory {d}/traj_hover.csv -o log.parquet", REFUSED, ["traj_hover.csv", "no sample touches the sensor", "--force"]),
    # fit: options and outputs
    ("fit-no-logs", "fit -o fit", REFUSED, ["fit:", "LOG"]),
    ("fit-no-output", FIT, REFUSED, ["fit:", "-o/--output"]),
    ("fit-missing-log", "fit {d}/nowhere.parquet -o fit", REFUSED, ["nowhere.parquet", "no such log file"]),
    ("fit-txt-log", "fit {d}/log.txt -o fit", REFUSED, ["log.txt", "a log is a Parquet or CSV file"]),
    ("fit-out-under-log", FIT + " -o {d}/elastic.parquet/fit", REFUSED, ["elastic.parquet is a file, not a folder"]),
    ("fit-out-is-file", FIT + " -o {d}/afile", REFUSED, ["afile", "is a file, not a folder"]),
    ("fit-out-unwritable", FIT + " -o /proc/fit", REFUSED, ["/proc/fit", "cannot write in /proc/"]),
    ("fit-terms-many", FIT + " -o fit --terms 9", REFUSED, ["--terms", "0 to 8 Prony terms"]),
    ("fit-terms-text", FIT + " -o fit --terms some", REFUSED, ["--terms", "'some'"]),
    ("fit-terms-negative", FIT + " -o fit --terms -1", REFUSED, ["--terms"]),
    ("fit-solver", FIT + " -o fit --solver newton", REFUSED, ["--solver", "invalid choice: 'newton'"]),
    ("fit-rays", FIT + " -o fit --rays 0", REFUSED, ["--rays"]),
    ("fit-wrong-sensor", FIT + " -o fit --sensor sphere8", REFUSED, ["elastic.parquet", "sensor", "'pad5x5', not 'sphere8'"]),
    ("fit-mapping-missing", "fit {d}/rig.csv --lumped -o fit --mapping {d}/nowhere.json", REFUSED, ["nowhere.json"]),
    ("fit-lumped-tare", "fit {d}/lumped.parquet --lumped --tare -o fit", REFUSED, ["--tare", "leave --tare out"]),
    ("fit-lumped-drift", "fit {d}/lumped.parquet --lumped --drift sometimes -o fit", REFUSED, ["--drift", "'sometimes'"]),
    ("fit-lumped-starts", "fit {d}/lumped.parquet --lumped --starts 9 -o fit", REFUSED, ["--starts"]),
    # fit: log files
    ("log-garbage-parquet", "fit {d}/garbage.parquet -o fit", REFUSED, ["garbage.parquet", "not a readable Parquet file"]),
    ("log-no-metadata", "fit {d}/no_metadata.parquet -o fit", REFUSED, ["no_metadata.parquet", "no hydrotact metadata", "--mapping"]),
    ("log-csv-no-json", "fit {d}/rig.csv -o fit", REFUSED, ["rig.csv", "no metadata document rig.json", "--mapping"]),
    ("log-binary-csv", "fit {d}/garbage.csv -o fit", REFUSED, ["garbage.csv", "not a CSV text file", "binary"]),
    ("log-semicolon-csv", "fit {d}/semicolon.csv -o fit", REFUSED, ["semicolon.csv", "separates fields by ';'"]),
    ("log-short-csv", "fit {d}/short.csv -o fit", REFUSED, ["short.csv"]),
    ("log-hpa", "fit {d}/hpa.parquet -o fit", REFUSED, ["hpa.parquet", "column 'b00', row 1", "outside the BMP388's range", "in hPa or mbar?"]),
    ("log-x50", "fit {d}/x50.parquet -o fit", REFUSED, ["x50.parquet", "column 'b00', row 1", "outside the BMP388's range"]),
    ("log-time-ms", "fit {d}/ms.parquet -o fit", REFUSED, ["ms.parquet", "column 'time'", "rate_hz is 100 Hz", "time in ms?"]),
    ("log-constant", "fit {d}/constant.parquet -o fit", REFUSED, ["constant.parquet", "no channel varies"]),
    ("log-negative-elastic", "fit {d}/negative.parquet -o fit", REFUSED, ["negative.parquet", "column 'b22'", "elastic pressure", "is negative"]),
    ("log-twice", "fit {d}/elastic.parquet {d}/elastic.parquet -o fit", REFUSED, ["elastic.parquet", "same samples as", "√2"]),
    ("log-twice-two-formats", "fit {d}/elastic.parquet {d}/elastic.csv -o fit", REFUSED, ["elastic.csv", "same samples as"]),
    ("log-unknown-sensor", "fit {d}/other_sensor.parquet -o fit", REFUSED, ["other_sensor.parquet", "sensor: 'nosuch' is neither a built-in sensor"]),
    ("log-bad-probe", "fit {d}/bad_probe.parquet -o fit", REFUSED, ["bad_probe.parquet", "probe:", "unknown probe 'cube:a=1'"]),
    ("fit-two-sensors", "fit {d}/elastic.parquet {d}/elastic_copy.parquet -o fit --terms 0", WARNED, ["2 sensors (pad5x5, ", "sensor_copy.json)", "same elastomer"]),
    ("log-swapped-channel-names", "fit {d}/swapped.parquet -o fit --terms 0", WARNED, ["reduced χ²", "channel names"]),
    ("log-nan", "fit {d}/nan.parquet -o fit", REFUSED, ["nan.parquet", "column 'b00', row 5: missing value"]),
    ("log-time-backwards", "fit {d}/backwards.parquet -o fit", REFUSED, ["backwards.parquet", "column 'time', row 2", "goes back"]),
    ("log-wrong-count", "fit {d}/wrong_count.parquet -o fit", REFUSED, ["wrong_count.parquet", "24 channel columns", "25 taxels"]),
    ("log-unknown-column", "fit {d}/unknown_column.parquet -o fit", REFUSED, ["unknown_column.parquet", "unknown column 'colour'"]),
    ("log-bad-format", "fit {d}/bad_format.parquet -o fit", REFUSED, ["bad_format.parquet", "format"]),
    ("log-bad-reference", "fit {d}/bad_reference.parquet -o fit", REFUSED, ["bad_reference.parquet", "pressure", "gauge"]),
    ("lumped-two-sensors", "fit {d}/lumped.parquet {d}/lumped_other_sensor.parquet --lumped -o fit", REFUSED,
        ["lumped_other_sensor.parquet", "from sensor 'other'", "one sensor's channel law"]),
    # fit: column mappings
    ("map-scale-zero", "fit {d}/rig.csv --lumped -o fit --mapping {d}/map_scale0.json", REFUSED, ["map_scale0.json", "columns.indentation.scale"]),
    ("map-kpa-for-hpa", "fit {d}/rig_hpa.csv --lumped -o fit --mapping {d}/map_kpa.json", REFUSED, ["rig_hpa.csv", "column", "outside the range of a barometer in air"]),
    ("map-hpa-as-pa", "fit {d}/rig_hpa.csv --lumped -o fit --mapping {d}/map_hpa_as_pa.json", REFUSED, ["rig_hpa.csv", "in hPa or mbar?"]),
    ("map-time-ms", "fit {d}/rig.csv --lumped -o fit --mapping {d}/map_ms.json", REFUSED, ["rig.csv", "column 'time'", "rate_hz is 50 Hz"]),
    ("map-missing-column", "fit {d}/rig.csv --lumped -o fit --mapping {d}/map_missing_column.json", REFUSED, ["rig.csv", "p9"]),
    ("map-unknown-unit", "fit {d}/rig.csv --lumped -o fit --mapping {d}/map_unit.json", REFUSED, ["map_unit.json", "time.unit", "fortnight"]),
    ("map-wrong-kind", "fit {d}/rig.csv --lumped -o fit --mapping {d}/map_kind.json", REFUSED, ["map_kind.json", "channels[0].unit", "'mm' is a length unit"]),
    ("map-malformed", "fit {d}/rig.csv --lumped -o fit --mapping {d}/map_malformed.json", REFUSED, ["map_malformed.json", "not valid JSON"]),
    ("map-semicolon", "fit {d}/rig_semicolon.csv --lumped -o fit --mapping {d}/map.json", REFUSED, ["rig_semicolon.csv", "separates fields by ';'", "csv.delimiter"]),
    ("map-decimal-comma", "fit {d}/rig_decimal_comma.csv --lumped -o fit --mapping {d}/map.json", REFUSED, ["rig_decimal_comma.csv", "decimal comma"]),
    ("map-decimal-comma-delimited", "fit {d}/rig_decimal_comma.csv --lumped -o fit --mapping {d}/map_semicolon.json", REFUSED, ["rig_decimal_comma.csv", "row 1", "a decimal comma?"]),
    # compare
    ("compare-no-fit", "compare {d}/nowhere {d}/lumped.parquet -o cmp", REFUSED, ["nowhere"]),
    ("compare-fit-is-file", "compare {d}/afile {d}/lumped.parquet -o cmp", REFUSED, ["afile"]),
    ("compare-tare", "compare {d}/nowhere {d}/lumped.parquet -o cmp --tare sometimes", REFUSED, ["--tare", "'sometimes'"]),
    ("compare-home", "compare {d}/nowhere {d}/lumped.parquet -o cmp --home guess", REFUSED, ["--home", "invalid choice: 'guess'"]),
    ("compare-out-is-file", "compare {d}/nowhere {d}/lumped.parquet -o {d}/afile", REFUSED, ["afile", "is a file, not a folder"]),
    # evaluate, predict, export: models damaged, logs that do not fit, outputs that cannot be written
    ("evaluate-no-model", "evaluate {d}/nowhere {d}/baro.parquet", REFUSED, ["nowhere", "model.json", "no such file"]),
    ("evaluate-model-is-file", "evaluate {d}/afile {d}/baro.parquet", REFUSED, ["afile"]),
    ("evaluate-model-channels", "evaluate {d}/model_channels {d}/baro.parquet", REFUSED, ["model_channels/model.json", "inputs disagree", "channels 8"]),
    ("evaluate-model-no-spec", "evaluate {d}/model_no_spec {d}/baro.parquet", REFUSED, ["model_no_spec/model.json", "spec: is missing"]),
    ("evaluate-model-architecture", "evaluate {d}/model_architecture {d}/baro.parquet", REFUSED, ["model.json", "spec.architecture", "lstm"]),
    ("evaluate-model-std-zero", "evaluate {d}/model_std_zero {d}/baro.parquet", REFUSED, ["model.json", "normaliser.std_Pa", "> 0"]),
    ("evaluate-model-best-epoch", "evaluate {d}/model_best_epoch {d}/baro.parquet", REFUSED, ["model.json", "best_epoch: 7", "1 epochs"]),
    ("evaluate-model-format", "evaluate {d}/model_format {d}/baro.parquet", REFUSED, ["model.json", "not a hydrotact estimator", "hydrotact.model"]),
    ("evaluate-model-not-json", "evaluate {d}/model_not_json {d}/baro.parquet", REFUSED, ["model_not_json/model.json", "not JSON"]),
    ("evaluate-model-no-weights", "evaluate {d}/model_no_weights {d}/baro.parquet", REFUSED, ["model_no_weights/weights.npz"]),
    ("evaluate-model-nan-weights", "evaluate {d}/model_nan {d}/baro.parquet", REFUSED, ["model_nan/weights.npz", "not finite"]),
    ("evaluate-no-labels", "evaluate {d}/model {d}/baro_unlabelled.parquet", REFUSED, ["baro_unlabelled.parquet", "'fx'"]),
    ("evaluate-other-sensor-log", "evaluate {d}/model {d}/lumped.parquet", REFUSED, ["lumped.parquet", "no channel", "the model reads"]),
    ("evaluate-elastic-log", "evaluate {d}/model {d}/elastic.parquet", REFUSED, ["elastic.parquet", "absolute barometer readings"]),
    ("evaluate-out-is-file", "evaluate {d}/model {d}/baro.parquet -o {d}/afile", REFUSED, ["afile", "is a file, not a folder"]),
    ("evaluate-out-unwritable", "evaluate {d}/model {d}/baro.parquet -o /proc/evaluation", REFUSED, ["/proc/evaluation", "cannot write"]),
    ("predict-out-csv", "predict {d}/model {d}/baro.parquet -o estimates.csv", REFUSED, ["estimates.csv", "*.parquet"]),
    ("predict-out-unwritable", "predict {d}/model {d}/baro.parquet -o /proc/estimates.parquet", REFUSED, ["/proc/estimates.parquet", "cannot write"]),
    ("predict-out-is-folder", "predict {d}/model {d}/baro.parquet -o afolder.parquet", REFUSED, ["afolder.parquet", "is a folder"]),
    ("predict-no-log", "predict {d}/model {d}/nowhere.parquet -o estimates.parquet", REFUSED, ["nowhere.parquet"]),
    ("predict-other-sensor-log", "predict {d}/model {d}/lumped.parquet -o estimates.parquet", REFUSED, ["lumped.parquet", "no channel"]),
    ("predict-model-channels", "predict {d}/model_channels {d}/baro.parquet -o estimates.parquet", REFUSED, ["model.json", "inputs disagree"]),
    ("export-proc", "export {d}/model -o /proc/model.h", REFUSED, ["/proc/model.h", "cannot write in /proc/"]),
    ("export-onto-folder", "export {d}/model -o afolder.h", REFUSED, ["afolder.h", "is a folder"]),
    ("export-not-a-header", "export {d}/model -o {d}", REFUSED, ["*.h"]),
    ("export-nan-weights", "export {d}/model_nan -o model.h", REFUSED, ["model_nan/weights.npz", "not finite"]),
    ("export-model-list", "export {d}/model_list.json -o model.h", REFUSED, ["model_list.json"]),
    ("export-earlier-output-kept", "export {d}/model_no_spec -o earlier.h", REFUSED, ["spec: is missing"]),
    ("export-format", "export {d}/model --format onnx -o model.h", REFUSED, ["--format", "'onnx'"]),
    ("train-no-dataset", "train {d}/nowhere -o trained", REFUSED, ["nowhere"]),
    ("train-dataset-is-a-log", "train {d}/baro.parquet -o trained", REFUSED, ["baro.parquet"]),
    ("train-out-is-file", "train {d}/nowhere -o {d}/afile", REFUSED, ["afile", "is a file, not a folder"]),
    ("train-out-unwritable", "train {d}/nowhere -o /proc/trained", REFUSED, ["/proc/trained", "cannot write"]),
    # train on a dataset folder that is damaged, or with settings it cannot take: refused before a model folder is made
    ("train-split-past-rows", "train {d}/ds_split -o trained", REFUSED, ["ds_split/manifest.json", "split.train[0]", "875 rows"]),
    ("train-shard-missing", "train {d}/ds_no_shard -o trained", REFUSED, ["ds_no_shard/shard-00000.parquet", "missing"]),
    ("train-shard-changed", "train {d}/ds_bad_sha -o trained", REFUSED, ["ds_bad_sha/shard-00000.parquet", "SHA-256"]),
    ("train-unfinished-dataset", "train {d}/ds_unfinished -o trained", REFUSED, ["ds_unfinished", "no manifest.json", "has not finished"]),
    ("train-manifest-not-json", "train {d}/ds_garbage -o trained", REFUSED, ["ds_garbage/manifest.json", "not valid JSON"]),
    ("train-hidden-zero", "train {d}/dataset --hidden 0,8 -o trained", REFUSED, ["hidden", "at least 1", "0,8"]),
    ("train-sequence-past-the-recordings", "train {d}/dataset --sequence-length 100000 -o trained", REFUSED, ["sequence-length 100000", "383 samples", "at most 383"]),
    ("train-epochs-zero", "train {d}/dataset --max-epochs 0 -o trained", REFUSED, ["max-epochs", "got 0"]),
    ("train-batch-zero", "train {d}/dataset --batch-size 0 -o trained", REFUSED, ["batch-size", "got 0"]),
    ("train-learning-rate-negative", "train {d}/dataset --learning-rate -1 -o trained", REFUSED, ["learning-rate", "(0, 1)", "-1"]),
    ("train-target-unknown", "train {d}/dataset --targets fx,colour -o trained", REFUSED, ["--targets", "'colour'"]),
    ("evaluate-dataset-of-another-sensor", "evaluate {d}/model {d}/dataset", REFUSED, ["dataset: channels b0, b1", "the model reads b00"]),
    # generate: every setting checked before any work, named by its option
    ("generate-events-zero", "generate --sensor pad5x5 --events 0 -o ds", REFUSED, ["--events", "got 0"]),
    ("generate-stage-with-tilt", "generate --sensor pad5x5 --regime stage --max-tilt 10 -o ds", REFUSED, ["--max-tilt", "--regime stage"]),
    ("generate-regime-unknown", "generate --sensor pad5x5 --regime orbit -o ds", REFUSED, ["--regime", "'orbit'"]),
    ("generate-speed-range-backwards", "generate --sensor pad5x5 --speed-range 0.02,0.01 -o ds", REFUSED, ["--speed-range", "LOW <= HIGH"]),
    ("generate-hold-negative", "generate --sensor pad5x5 --hold-range -1,2 -o ds", REFUSED, ["--hold-range"]),
    ("generate-rate-zero", "generate --sensor pad5x5 --rate 0 -o ds", REFUSED, ["--rate:", "1-10000 Hz"]),
    ("generate-rays-zero", "generate --sensor pad5x5 --rays 0 -o ds", REFUSED, ["--rays:", "1-4096"]),
    ("generate-test-fraction", "generate --sensor pad5x5 --test-fraction 1.5 -o ds", REFUSED, ["--test-fraction", "0-0.9"]),
    ("generate-noise-negative", "generate --sensor pad5x5 --noise -1 -o ds", REFUSED, ["--noise", "-1 Pa"]),
    ("generate-stage-x-backwards", "generate --sensor pad5x5 --regime stage --stage-x-range 5,1 -o ds", REFUSED, ["--stage-x-range", "LOW <= HIGH"]),
    ("generate-shard-rows", "generate --sensor pad5x5 --shard-rows 0 -o ds", REFUSED, ["--shard-rows", "at least 100"]),
    ("generate-out-is-file", "generate --sensor pad5x5 -o {d}/afile", REFUSED, ["afile", "is a file, not a folder"]),
    ("generate-foreign-folder", "generate --sensor pad5x5 -o {d}", REFUSED, ["not part of a hydrotact dataset"]),
    ("generate-unknown-sensor", "generate --sensor pad6x6 -o ds", REFUSED, ["pad6x6"]),
    ("generate-into-another-dataset", "generate --sensor pad5x5 --events 2 -o {d}/dataset", REFUSED, ["holds another dataset (sphere8, 2 events, seed 1)", "nothing written"]),
    ("generate-into-another-run", "generate --sensor pad5x5 --events 2 -o {d}/ds_unfinished", REFUSED, ["ds_unfinished", "unfinished run of another dataset"]),
    ("generate-ray-no-port", "generate --sensor pad5x5 --ray nohost -o ds", REFUSED, ["--ray nohost", "no Ray cluster answers"]),
    ("generate-unknown-probe", "generate --sensor pad5x5 --probe cube:a=1 -o ds", REFUSED, ["--probe", "unknown probe 'cube:a=1'"]),
    ("generate-negative-material", "generate --sensor pad5x5 --material {d}/material_negative.json -o ds", REFUSED, ["material_negative.json", "long_term_modulus_Pa.value"]),
    ("generate-force-from-zero", "generate --sensor pad5x5 --force-range 0,1 -o ds", REFUSED, ["--force-range", "LOW > 0 N"]),
    # generate on a Ray cluster that is not there: refused at once (Ray's own init waited over 300 s), nothing written
    ("generate-dead-ray", "generate --sensor pad5x5 --events 2 --ray 127.0.0.1:9 -o ds", REFUSED, ["--ray 127.0.0.1:9", "no Ray cluster answers at 127.0.0.1:9"]),
    # design: impossible constraints refused before any work, no .partial left
    ("design-margin-wider-than-the-pad", "design --sensor pad5x5 --margin 0.02 --restarts 0 -o lay.json", REFUSED, ["cannot place 25 barometers", "--margin"]),
    ("design-spacing-wider-than-the-pad", "design --sensor pad5x5 --spacing 0.05 -o lay.json", REFUSED, ["cannot place 25 barometers", "50 mm apart", "--spacing"]),
    ("design-other-count-no-start", "design --sensor pad5x5 --barometers 9 --restarts 0 -o lay.json", REFUSED, ["--restarts 0", "--barometers 9", "of 25 barometers"]),
    ("design-out-csv", "design --sensor pad5x5 -o lay.csv", REFUSED, ["lay.csv", "*.json"]),
    ("design-no-barometers", "design --sensor pad5x5 --barometers 0 -o lay.json", REFUSED, ["--barometers", "at least 1, got 0"]),
    ("design-one-too-many", "design --sensor pad5x5 --barometers 26 --restarts 0 -o lay.json", REFUSED, ["cannot place 26 barometers", "own layout holds 25"]),
    ("design-unknown-probe", "design --sensor pad5x5 --probe cube:a=1 -o lay.json", REFUSED, ["--probe", "unknown probe 'cube:a=1'"]),
    ("design-noise-negative", "design --sensor pad5x5 --noise -1 -o lay.json", REFUSED, ["--noise", "non-negative", "-1"]),
    ("design-depth-range-backwards", "design --sensor pad5x5 --target depth --depth-range 0.002,0.001 -o lay.json", REFUSED, ["--depth-range", "LOW <= HIGH"]),
    ("design-unknown-sensor", "design --sensor nosuch -o lay.json", REFUSED, ["nosuch", "neither a built-in sensor"]),
    ("design-modulus-negative", "design --sensor pad5x5 --modulus -5 -o lay.json", REFUSED, ["--modulus", "positive", "-5"]),
    ("design-material-tau-zero", "design --sensor pad5x5 --material {d}/material_tau0.json -o lay.json", REFUSED, ["material_tau0.json", "prony_terms[0].tau_s.value"]),
    # compare, predict, export: inputs of the wrong kind
    ("compare-model-for-a-fit", "compare {d}/model {d}/lumped.parquet -o cmp", REFUSED, ["model: no material.json", "hydrotact fit --lumped"]),
    ("compare-tare-zero-seconds", "compare {d}/nowhere {d}/lumped.parquet -o cmp --tare first:0", REFUSED, ["--tare", "first:SECONDS", "'first:0'"]),
    ("predict-elastic-log", "predict {d}/model {d}/elastic.parquet -o estimates.parquet", REFUSED, ["elastic.parquet", "absolute barometer readings"]),
    ("predict-nan-weights", "predict {d}/model_nan {d}/baro.parquet -o estimates.parquet", REFUSED, ["model_nan/weights.npz", "not finite"]),
    ("export-no-model", "export {d}/nowhere -o model.h", REFUSED, ["nowhere/model.json", "no such file"]),
    # demo
    ("demo-out-is-file", "demo -o {d}/afile", REFUSED, ["afile", "is a file, not a folder"]),
    ("demo-out-unwritable", "demo -o /proc/demo", REFUSED, ["/proc/demo", "cannot write"]),
    # accepted, with a warning and its figures
    ("sim-barometer-saturates", "simulate --sensor pad5x5 --probe cylinder:d=2mm --rays 16 --trajectory {d}/traj.csv -o log.parquet --barometer --json", WARNED,
        ["log.parquet", "readings on 1 channels reached the BMP388's range", "saturated_samples"]),
    ("fit-masks-clipped-readings", "fit {d}/clipped.parquet -o fit --terms 0 --json", WARNED, ["clipped.parquet", "sit at the part's range limits", "masked"]),
    # inputs that look odd but are right
    ("traj-in-mm-with-units", SIM + " --trajectory {d}/traj_mm.csv --units mm -o log.parquet --json", CLEAR, []),
    ("mesh-edge-in-mm", "mesh pad5x5 --edge-length 1 --units mm --json", CLEAR, []),
    ("mould-tray", "mesh --mould {d}/tray.stl --units mm --board zmin --edge-length 1 --json", CLEAR, []),
    ("contact-on-a-mesh-file", "contact --mesh {d}/box.vtu --probe plane --at 0,0,0.1mm --modulus 2e5 --json", CLEAR, []),
    ("traj-bom-crlf", SIM + " --trajectory {d}/traj_crlf_bom.csv -o log.parquet --json", CLEAR, []),
    ("fit-short-log-4-terms", "fit {d}/baro.parquet -o fit --terms 4 --max-steps 60", WARNED, ["not identified by these logs", "τ"]),
    ("fit-short-log-auto-terms", "fit {d}/baro.parquet -o fit --terms auto --json", CLEAR, []),
]

SETUP = {  # cases whose working folder holds something first
    "mesh-out-is-folder": lambda cwd: (cwd / "afolder.vtu").mkdir(),
    "sim-out-is-folder": lambda cwd: (cwd / "afolder.parquet").mkdir(),
    "mesh-earlier-output-kept": lambda cwd: (cwd / "earlier.vtu").write_bytes(EARLIER),
    "sim-earlier-output-kept": lambda cwd: (cwd / "earlier.parquet").write_bytes(EARLIER),
    "predict-out-is-folder": lambda cwd: (cwd / "afolder.parquet").mkdir(),
    "export-onto-folder": lambda cwd: (cwd / "afolder.h").mkdir(),
    "export-earlier-output-kept": lambda cwd: (cwd / "earlier.h").write_bytes(EARLIER),
}


def _checksums(folder) -> dict:
    import hashlib

    return {str(p.relative_to(folder)): (hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "folder") for p in sorted(folder.rglob("*"))}


def test_the_table_is_large_and_distinct():
    names = [case[0] for case in CASES]
    assert len(names) == len(set(names)), "case names repeat"
    assert len({case[1] for case in CASES}) == len(CASES), "two cases run the same command"
    assert len(CASES) >= 150, len(CASES)


@pytest.mark.parametrize(("argv", "kind", "fragments"), [case[1:] for case in CASES], ids=[case[0] for case in CASES])
def test_bad_input_table(request, inputs, tmp_path, monkeypatch, capsys, argv, kind, fragments):
    import shlex

    from hydrotact.cli import main

    monkeypatch.chdir(tmp_path)
    SETUP.get(request.node.callspec.id, lambda cwd: None)(tmp_path)
    before = (_checksums(inputs), _checksums(tmp_path))
    try:
        code = main(shlex.split(argv.format(d=inputs)))
    except SystemExit as exit_:
        code = exit_.code
    out, err = capsys.readouterr()
    assert "Traceback" not in err + out
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith(("simulating", "\r"))]
    if kind == REFUSED:
        assert code == 2, (code, out, err)
        assert len(lines) == 1 and lines[0].startswith("hydrotact: error: "), err
        for fragment in fragments:
            assert fragment in lines[0], (fragment, lines[0])
        assert (_checksums(inputs), _checksums(tmp_path)) == before, "a refused run wrote or changed a file"
        return
    assert code == 0, (code, err)
    assert _checksums(inputs) == before[0]
    warnings_ = [line for line in lines if line.startswith("hydrotact: warning: ")]
    if kind == WARNED:
        assert any(all(fragment in line for fragment in fragments) for line in warnings_), err
    else:
        assert not warnings_, err
