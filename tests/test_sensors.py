"""Sensor specs: the built-ins, the schema, units, round trips, and one clear message
for every kind of bad file."""

import copy
import json
import math

import numpy as np
import pytest
import trimesh
from helpers import box_surface

from hydrotact import HydrotactError
from hydrotact._schemas import load_schema, validate
from hydrotact.mesh import calc_signed_volumes
from hydrotact.sensors import BUILTIN_SENSORS, Part, SensorSpec, known_parts, load_sensor, with_receptive_fields
from hydrotact.sensors._builtins import builtin_documents, builtin_text
from hydrotact.sensors._inside import calc_winding_numbers, find_points_outside_surface, find_points_outside_tets

EXPECTED_COUNTS = {"pad5x5": 25, "sphere8": 8, "ellipsoid8": 8, "sphere8-cones": 8, "ellipsoid8-cones": 8}


def _builtin(name):
    return copy.deepcopy(builtin_documents()[name])


def _write(tmp_path, document, name="my_sensor.json"):
    path = tmp_path / name
    path.write_text(document if isinstance(document, str) else json.dumps(document))
    return path


def _assert_fails(path, *fragments):
    with pytest.raises(HydrotactError) as info:
        load_sensor(path)
    message = str(info.value)
    assert "\n" not in message, message
    assert message.startswith(f"{path}: "), message
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    return message


# --- the built-ins ---------------------------------------------------------------------


@pytest.mark.parametrize("name", BUILTIN_SENSORS)
def test_builtins_load(name):
    spec = load_sensor(name)
    assert isinstance(spec, SensorSpec)
    assert spec.name == name and spec.source == f"built-in {name}"
    assert spec.num_taxels == EXPECTED_COUNTS[name] == len(spec.taxel_names) == len(set(spec.taxel_names))
    assert spec.taxel_positions_S.shape == spec.taxel_axes_S.shape == (spec.num_taxels, 3)
    assert spec.taxel_positions_S.dtype == spec.taxel_axes_S.dtype == spec.taxel_field_sizes.dtype == np.float64
    np.testing.assert_allclose(np.linalg.norm(spec.taxel_axes_S, axis=1), 1.0, rtol=0, atol=1e-12)
    assert (spec.taxel_axes_S[:, 2] > 0).all()  # every barometer looks up into the elastomer
    assert spec.part == known_parts()["BMP388"]
    assert spec.part.lsb_pa == 0.016 and spec.part.range_pa == (30000.0, 125000.0)
    assert "datasheet" in spec.part.description
    assert not spec.taxel_positions_S.flags.writeable


def test_builtin_files_are_what_the_generator_writes():
    from importlib.resources import files

    for name in BUILTIN_SENSORS:
        assert (files("hydrotact.sensors") / "data" / f"{name}.json").read_text() == builtin_text(name), name


def test_builtin_files_validate_against_the_schema():
    import jsonschema

    jsonschema.Draft202012Validator.check_schema(load_schema("sensor"))
    for name in BUILTIN_SENSORS:
        validate(builtin_documents()[name], "sensor", name)


def test_pad_grid():
    spec = load_sensor("pad5x5")
    centres = np.array([-4.4, -2.2, 0.0, 2.2, 4.4]) * 1e-3
    for index, name in enumerate(spec.taxel_names):
        row, col = divmod(index, 5)
        assert name == f"b{row}{col}"
        np.testing.assert_array_equal(spec.taxel_positions_S[index], [centres[col], centres[row], 0.0])
    np.testing.assert_allclose(np.diff(np.unique(spec.taxel_positions_S[:, 0])), 2.2e-3, rtol=1e-12)
    np.testing.assert_array_equal(spec.taxel_axes_S, np.tile([0.0, 0.0, 1.0], (25, 1)))
    assert spec.taxel_field_kinds == ("disk",) * 25
    np.testing.assert_allclose(spec.taxel_field_sizes, 1.1e-3, rtol=1e-15)
    assert spec.contact_center_S is None and spec.theta_range is None and spec.phi_range is None


@pytest.mark.parametrize(
    ("name", "inner", "outer", "center_z", "theta", "phi"),
    [
        ("sphere8", (3.0, 3.0, 1.0), (6.0, 6.0, 2.0), 5.0, (-45, 45), (-135, 45)),
        ("ellipsoid8", (0.33 * 10.7, 0.33 * 9.0, 0.8), (0.6 * 10.7, 0.6 * 9.0, 1.5), 3.4, (-40, 40), (-72, 72)),
    ],
)
@pytest.mark.parametrize("cones", [False, True], ids=["elastic", "cones"])
def test_curved_layouts(name, inner, outer, center_z, theta, phi, cones):
    """The curved built-ins and their -cones twins: one layout, two barometer models
    (the elastomer's pressure over a 0.5 mm port, or the 40 deg cone on the skin)."""
    spec = load_sensor(name + "-cones" if cones else name)
    assert spec.taxel_names == tuple(f"b{i}" for i in range(8))
    expected_positions, expected_axes = [[0.0, 0.0, inner[2]]], [[0.0, 0.0, 1.0]]
    for (rx, ry, z), tilt, azimuths in ((inner, 30, (0, 90, 180, 270)), (outer, 60, (60, 180, 300))):
        for az in np.radians(azimuths):
            t = math.radians(tilt)
            expected_positions.append([rx * math.cos(az), ry * math.sin(az), z])
            expected_axes.append([math.sin(t) * math.cos(az), math.sin(t) * math.sin(az), math.cos(t)])
    np.testing.assert_allclose(spec.taxel_positions_S, np.array(expected_positions) * 1e-3, rtol=0, atol=1e-12)
    np.testing.assert_allclose(spec.taxel_axes_S, expected_axes, rtol=0, atol=1e-9)
    if cones:
        assert spec.taxel_field_kinds == ("cone",) * 8
        np.testing.assert_allclose(spec.taxel_field_sizes, math.radians(40.0), rtol=1e-15)
    else:
        assert spec.taxel_field_kinds == ("elastic",) * 8 and spec.taxel_elastic_readings == ("pressure",) * 8
        np.testing.assert_allclose(spec.taxel_field_sizes, 0.5e-3, rtol=1e-15)
        assert spec.poisson_ratio == 0.49
    assert spec.geometry.seed == name
    np.testing.assert_allclose(spec.contact_center_S, [0.0, 0.0, center_z * 1e-3], rtol=1e-15)
    np.testing.assert_allclose(spec.theta_range, np.radians(theta), rtol=1e-15)
    np.testing.assert_allclose(spec.phi_range, np.radians(phi), rtol=1e-15)


@pytest.mark.parametrize("name", BUILTIN_SENSORS)
def test_builtin_taxels_lie_in_their_meshes(name):
    spec = load_sensor(name)
    mesh = spec.make_mesh(check=False)
    vertices, tets = np.asarray(mesh.vertices), np.asarray(mesh.tets)
    # Point-in-tet with no boundary allowance for the ports strictly inside; pad ports
    # sit on the bonded base (z = 0) and must be on a boundary face there.
    assert len(find_points_outside_tets(spec.taxel_positions_S, vertices, tets, np.asarray(mesh.boundary_faces), 0.0)) == 0
    spec.check_against_mesh(mesh)
    # and a port moved out through the top is caught by the same check
    lifted = spec.taxel_positions_S + [0.0, 0.0, float(vertices[:, 2].max()) + 1e-3]
    assert len(find_points_outside_tets(lifted, vertices, tets, np.asarray(mesh.boundary_faces), 1e-6)) == spec.num_taxels


def test_winding_numbers():
    surface = box_surface((2.0, 2.0, 2.0))
    points = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 3.0], [0.9, 0.9, 1.9], [1.5, 0.0, 1.0]])
    np.testing.assert_allclose(calc_winding_numbers(points, surface.vertices, surface.faces), [1, 0, 1, 0], atol=1e-12)
    on_skin = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 2.0], [0.3, -1.0, 0.5]])
    assert len(find_points_outside_surface(on_skin, surface.vertices, surface.faces, 1e-12)) == 0
    assert list(find_points_outside_surface(on_skin + [0, 0, -1e-6], surface.vertices, surface.faces, 1e-9)) == [0]


# --- round trips and units -------------------------------------------------------------


def _assert_same(a, b):
    assert (a.name, a.description, a.geometry, a.part, a.taxel_names, a.taxel_field_kinds) == (
        b.name, b.description, b.geometry, b.part, b.taxel_names, b.taxel_field_kinds,
    )
    for field in ("taxel_positions_S", "taxel_axes_S", "taxel_field_sizes", "contact_center_S"):
        x, y = getattr(a, field), getattr(b, field)
        assert (x is None) == (y is None), field
        if x is not None:
            np.testing.assert_allclose(x, y, rtol=1e-14, atol=1e-18, err_msg=field)
    for field in ("theta_range", "phi_range"):
        x, y = getattr(a, field), getattr(b, field)
        assert (x is None) == (y is None)
        if x is not None:
            np.testing.assert_allclose(x, y, rtol=1e-14)


@pytest.mark.parametrize("name", BUILTIN_SENSORS)
def test_to_json_round_trips(name, tmp_path):
    spec = load_sensor(name)
    document = spec.to_json()
    validate(document, "sensor", "to_json")
    assert document["units"] == {"length": "m", "angle": "rad"}
    path = _write(tmp_path, document, f"{name}_si.json")
    again = load_sensor(path)
    assert again.source == str(path)
    _assert_same(spec, again)
    _assert_same(spec, load_sensor(document))
    assert again.to_json() == document


def test_a_spec_switched_to_another_barometer_model():
    """`with_receptive_fields`: the same elastomer, layout and part, every barometer on
    the new model (its numbers in SI units, as to_json writes them), validated as a
    loaded file is (a bad field names the taxel's field)."""
    pad = load_sensor("pad5x5")
    elastic = with_receptive_fields(pad, {"kind": "elastic"})
    assert elastic.name == "pad5x5-elastic" and elastic.taxel_field_kinds == ("elastic",) * 25
    np.testing.assert_array_equal(elastic.taxel_positions_S, pad.taxel_positions_S)
    np.testing.assert_array_equal(elastic.taxel_axes_S, pad.taxel_axes_S)
    assert elastic.part == pad.part and elastic.geometry == pad.geometry
    cones = with_receptive_fields(load_sensor("sphere8"), {"kind": "cone", "half_angle": math.radians(40.0)}, name="sphere8-cones")
    assert cones.to_json() == load_sensor("sphere8-cones").to_json() | {"description": cones.description}
    with pytest.raises(HydrotactError, match="receptive_field"):
        with_receptive_fields(pad, {"kind": "cone"})  # a cone needs its half-angle


def test_units_are_converted(tmp_path):
    millimetres = _builtin("sphere8-cones")
    metres = copy.deepcopy(millimetres)
    metres["units"] = {"length": "m", "angle": "rad"}
    for taxel in metres["taxels"]:
        taxel["position"] = [v * 1e-3 for v in taxel["position"]]
        taxel["receptive_field"]["half_angle"] = math.radians(taxel["receptive_field"]["half_angle"])
    angles = metres["contact_angles"]
    angles["center"] = [v * 1e-3 for v in angles["center"]]
    angles["theta_range"] = [math.radians(v) for v in angles["theta_range"]]
    angles["phi_range"] = [math.radians(v) for v in angles["phi_range"]]
    micrometres = copy.deepcopy(millimetres)
    micrometres["units"]["length"] = "um"
    for taxel in micrometres["taxels"]:
        taxel["position"] = [v * 1e3 for v in taxel["position"]]
    micrometres["contact_angles"]["center"] = [v * 1e3 for v in micrometres["contact_angles"]["center"]]
    a = load_sensor(_write(tmp_path, millimetres, "mm.json"))
    _assert_same(a, load_sensor(_write(tmp_path, metres, "m.json")))
    _assert_same(a, load_sensor(_write(tmp_path, micrometres, "um.json")))
    np.testing.assert_allclose(a.taxel_positions_S[5], [3e-3, 3e-3 * math.sqrt(3), 2e-3], rtol=0, atol=1e-12)


def test_part_inline_and_axes_normalised(tmp_path):
    document = _builtin("pad5x5")
    document["part"] = {
        "name": "MyBaro", "lsb_pa": 0.5, "noise_rms_pa": 1.0, "rate_hz": 50, "range_pa": [90000, 110000], "ambient_pa": 100000,
    }
    document["taxels"][0]["axis"] = [0.0, 0.0, 7.5]
    spec = load_sensor(_write(tmp_path, document))
    assert spec.part == Part("MyBaro", 0.5, 1.0, 50.0, (90000.0, 110000.0), 100000.0)
    np.testing.assert_array_equal(spec.taxel_axes_S[0], [0.0, 0.0, 1.0])


def test_surface_geometry(tmp_path):
    surface = box_surface((6.0, 6.0, 3.0))  # in mm
    (tmp_path / "shapes").mkdir()
    surface.export(tmp_path / "shapes" / "block.stl")
    document = {
        "name": "block",
        "description": "a 6 x 6 x 3 mm block with two barometers",
        "units": {"length": "mm", "angle": "deg"},
        "geometry": {"kind": "surface", "path": "shapes/block.stl", "core_plane_z": 0.0, "edge_length": 1.0},
        "part": "BMP388",
        "taxels": [
            {"name": "left", "position": [-1.5, 0, 0], "axis": [0, 0, 1], "receptive_field": {"kind": "disk", "radius": 1}},
            {"name": "right", "position": [1.5, 0, 0.5], "axis": [0, 0, 1], "receptive_field": {"kind": "cone", "half_angle": 30}},
        ],
    }
    spec = load_sensor(_write(tmp_path, document))
    assert spec.geometry.kind == "surface" and spec.geometry.surface_units == "mm"
    assert spec.geometry.path == str((tmp_path / "shapes" / "block.stl").resolve())
    assert spec.geometry.edge_length == pytest.approx(1e-3) and spec.geometry.core_plane_z == 0.0
    np.testing.assert_allclose(spec.taxel_positions_S[1], [1.5e-3, 0.0, 0.5e-3])
    mesh = spec.make_mesh()
    lo, hi = np.asarray(mesh.vertices).min(axis=0), np.asarray(mesh.vertices).max(axis=0)
    np.testing.assert_allclose(hi - lo, [6e-3, 6e-3, 3e-3], rtol=1e-2)
    again = load_sensor(_write(tmp_path, spec.to_json(), "elsewhere.json"))
    _assert_same(spec, again)
    # the position check runs on load, against the closed surface
    document["taxels"][1]["position"] = [1.5, 0, 3.5]
    _assert_fails(_write(tmp_path, document, "above.json"), "taxels[1].position", "outside the surface block.stl")


def test_mould_geometry(tmp_path):
    """A sensor cast in a tray whose floor carries two pocket formers (2 x 2 x 1 mm):
    the cast's board side (the floor) down on z = 0, a barometer at each pocket's
    ceiling reading the elastomer's stress there."""
    from helpers import write_mould

    (tmp_path / "cad").mkdir()
    write_mould(tmp_path / "cad" / "tray.stl", ((0, 0, 0), (16, 8, 6)), [((2, 2, 2), (14, 6, 6.5))], formers=[((4, 3, 2), (6, 5, 3)), ((10, 3, 2), (12, 5, 3))])
    document = {
        "name": "cast",
        "description": "a 12 x 4 x 4 mm strip cast in a tray, two barometers in its pockets",
        "units": {"length": "mm", "angle": "deg"},
        "geometry": {"kind": "mould", "paths": ["cad/tray.stl"], "board": "zmin", "edge_length": 1.0},
        "part": "BMP388",
        "taxels": [
            {"name": f"p{k}", "position": [x, 0, 1], "axis": [0, 0, 1], "receptive_field": {"kind": "elastic", "port_radius": 0.5}} for k, x in enumerate((-3, 3))
        ],
    }
    spec = load_sensor(_write(tmp_path, document))
    assert spec.geometry.kind == "mould" and spec.geometry.surface_units == "mm" and spec.geometry.board == "zmin"
    assert spec.geometry.paths == (str((tmp_path / "cad" / "tray.stl").resolve()),)
    assert spec.is_elastic.all()
    document["taxels"][1]["receptive_field"]["reading"] = "cavity"  # the air sealed in its pocket
    assert load_sensor(_write(tmp_path, document, "sealed.json")).taxel_elastic_readings == ("pressure", "cavity")
    mesh = spec.make_mesh()
    np.testing.assert_allclose(float(np.sum(calc_signed_volumes(mesh.vertices, mesh.tets))), (12 * 4 * 4 - 2 * 4) * 1e-9, rtol=2e-3)
    lo, hi = np.asarray(mesh.vertices).min(axis=0), np.asarray(mesh.vertices).max(axis=0)
    np.testing.assert_allclose([lo, hi], [[-6e-3, -2e-3, 0.0], [6e-3, 2e-3, 4e-3]], atol=2e-5)  # within fTetWild's envelope
    again = load_sensor(_write(tmp_path, spec.to_json(), "elsewhere.json"))
    _assert_same(spec, again)
    assert again.geometry.paths == spec.geometry.paths and again.geometry.board == "zmin"
    # A port inside a pocket's former (air, not rubber) is outside the cast; a missing part is named.
    document["taxels"][1]["position"] = [3, 0, 0.5]
    _assert_fails(_write(tmp_path, document, "in_pocket.json"), "taxels[1].position", "outside the cast of tray.stl")
    document["geometry"]["paths"] = ["cad/tray.stl", "cad/lid.stl"]
    _assert_fails(_write(tmp_path, document, "no_lid.json"), "geometry.paths[1]: surface file", "lid.stl does not exist")


# --- bad files -------------------------------------------------------------------------


def _broken(tmp_path, name, edit):
    document = _builtin(name)
    edit(document)
    return _write(tmp_path, document)


def _set(path, value):
    def edit(document):
        *parents, last = path
        target = document
        for key in parents:
            target = target[key]
        target[last] = value

    return edit


def _delete(path):
    def edit(document):
        *parents, last = path
        target = document
        for key in parents:
            target = target[key]
        del target[last]

    return edit


BROKEN = {
    "missing field": ("pad5x5", _delete(["taxels", 3, "axis"]), ["taxels[3].axis: is missing"]),
    "missing top-level field": ("pad5x5", _delete(["units"]), ["units: is missing"]),
    "wrong type": ("pad5x5", _set(["taxels", 1, "position"], "here"), ["taxels[1].position: must be an array, got \"here\""]),
    "wrong item type": ("pad5x5", _set(["taxels", 1, "position", 2], "0"), ["taxels[1].position[2]: must be a number, got \"0\""]),
    "extra key": ("sphere8", _set(["taxels", 2, "colour"], "red"), ["taxels[2].colour: unknown field", "receptive_field"]),
    "extra key in a field": ("sphere8", _set(["taxels", 2, "receptive_field", "radius"], 1.0), ["taxels[2].receptive_field.radius: unknown field"]),
    "axis of 2 numbers": ("pad5x5", _set(["taxels", 3, "axis"], [0, 1]), ["taxels[3].axis: must have 3 numbers, got 2"]),
    "zero axis": ("sphere8", _set(["taxels", 4, "axis"], [0, 0, 0]), ["taxels[4].axis: must not be zero"]),
    "negative radius": ("pad5x5", _set(["taxels", 7, "receptive_field", "radius"], -1.1), ["taxels[7].receptive_field.radius: must be > 0, got -1.1"]),
    "half-angle 95 deg": ("sphere8-cones", _set(["taxels", 2, "receptive_field", "half_angle"], 95), ["taxels[2].receptive_field.half_angle: 95 deg is not in (0, 90)"]),
    "zero half-angle": ("sphere8-cones", _set(["taxels", 0, "receptive_field", "half_angle"], 0), ["taxels[0].receptive_field.half_angle: 0 deg is not in (0, 90)"]),
    "unknown field kind": ("sphere8", _set(["taxels", 1, "receptive_field", "kind"], "ring"), ["taxels[1].receptive_field.kind: must be one of \"disk\", \"cone\", \"elastic\", got \"ring\""]),
    "duplicate names": ("pad5x5", _set(["taxels", 6, "name"], "b00"), ["taxels[6].name: 'b00' is already the name of taxels[0]"]),
    "unknown part": ("pad5x5", _set(["part"], "BMP999"), ["part: unknown part 'BMP999'; the known parts are BMP388, MPL3115A2"]),
    "part of wrong type": ("pad5x5", _set(["part"], 388), ["part: must be a string or an object, got 388"]),
    "zero lsb": ("pad5x5", _set(["part"], {"name": "x", "lsb_pa": 0, "noise_rms_pa": 0.1, "rate_hz": 10, "range_pa": [1, 2], "ambient_pa": 1.5}), ["part.lsb_pa: must be > 0, got 0"]),
    "negative rate": ("pad5x5", _set(["part"], {"name": "x", "lsb_pa": 1, "noise_rms_pa": 0.1, "rate_hz": -10, "range_pa": [1, 2], "ambient_pa": 1.5}), ["part.rate_hz: must be > 0, got -10"]),
    "ambient out of range": ("pad5x5", _set(["part"], {"name": "x", "lsb_pa": 1, "noise_rms_pa": 0.1, "rate_hz": 10, "range_pa": [1,
        2], "ambient_pa": 3}), ["part.ambient_pa: 3 Pa is outside range_pa"]),
    "unknown units": ("pad5x5", _set(["units", "length"], "inch"), ["units.length: must be one of \"m\", \"mm\", \"um\", got \"inch\""]),
    "unknown angle units": ("sphere8", _set(["units", "angle"], "grad"), ["units.angle: must be one of \"rad\", \"deg\", got \"grad\""]),
    "unknown seed": ("pad5x5", _set(["geometry", "seed"], "cube9"), ["geometry.seed: must be one of \"pad5x5\", \"sphere8\", \"ellipsoid8\", got \"cube9\""]),
    "geometry without kind": ("pad5x5", _delete(["geometry", "kind"]), ["geometry.kind: is missing"]),
    "missing surface file": ("pad5x5", _set(["geometry"], {"kind": "surface", "path": "nowhere/shape.stl", "core_plane_z": 0,
        "edge_length": 1}), ["geometry.path: surface file", "nowhere/shape.stl does not exist"]),
    "not a surface file": ("pad5x5", _set(["geometry"], {"kind": "surface", "path": "shape.vtu", "core_plane_z": 0, "edge_length": 1}), ["geometry.path: shape.vtu is not a surface file"]),
    "surface missing edge length": ("pad5x5", _set(["geometry"], {"kind": "surface", "path": "shape.stl", "core_plane_z": 0}), ["geometry.edge_length: is missing"]),
    "position outside the pad": ("pad5x5", _set(["taxels", 12, "position"], [0.0, 0.0, 4.5]), ["taxels[12].position: (0, 0, 4.5) mm is outside the pad5x5 elastomer"]),
    "position below the PCB": ("pad5x5", _set(["taxels", 0, "position", 2], -0.1), ["taxels[0].position: ", "is outside the pad5x5 elastomer"]),
    "position outside the sphere": ("sphere8", _set(["taxels", 7, "position"], [8.0, 0.0, 12.0]), ["taxels[7].position: (8, 0, 12) mm is outside the sphere8 elastomer"]),
    "position outside the ellipsoid": ("ellipsoid8", _set(["taxels", 5, "position"], [10.0, 0.0, 6.0]), ["taxels[5].position: (10, 0, 6) mm is outside the ellipsoid8 elastomer"]),
    "theta range upside down": ("sphere8", _set(["contact_angles", "theta_range"], [45, -45]), ["contact_angles.theta_range: low end 45 must be below high end -45"]),
    "no taxels": ("pad5x5", _set(["taxels"], []), ["taxels: must not be empty"]),
    "empty name": ("pad5x5", _set(["name"], ""), ["name: must not be empty"]),
    "not an object": ("pad5x5", lambda d: d.clear(), ["name: is missing"]),
}


@pytest.mark.parametrize("case", list(BROKEN))
def test_broken_file(case, tmp_path):
    name, edit, fragments = BROKEN[case]
    _assert_fails(_broken(tmp_path, name, edit), *fragments)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("this is not json", "not valid JSON: Expecting value (line 1, column 1)"),
        ('{"name": "x",\n "units": }', "not valid JSON: Expecting value (line 2, column 11)"),
        ("[1, 2]", "(document): must be an object, got [1, 2]"),
        ('{"name": NaN}', "name: must be a finite number, got nan"),
    ],
)
def test_unreadable_file(text, fragment, tmp_path):
    _assert_fails(_write(tmp_path, text), fragment)


def test_nan_in_a_position(tmp_path):
    path = _write(tmp_path, json.dumps(_builtin("pad5x5")).replace('"position": [-4.4, -2.2, 0.0]', '"position": [-4.4, -2.2, NaN]'))
    _assert_fails(path, "taxels[5].position[2]: must be a finite number, got nan")


def test_unknown_sensor_name(tmp_path):
    with pytest.raises(HydrotactError, match="sphere9: neither a built-in sensor \\(pad5x5, sphere8, ellipsoid8, sphere8-cones, ellipsoid8-cones\\) nor an existing file"):
        load_sensor("sphere9")


def test_surface_that_is_not_closed(tmp_path):
    surface = box_surface((6.0, 6.0, 3.0))
    trimesh.Trimesh(surface.vertices, surface.faces[1:], process=False).export(tmp_path / "open.stl")
    document = _builtin("pad5x5")
    document["geometry"] = {"kind": "surface", "path": "open.stl", "core_plane_z": 0, "edge_length": 1}
    _assert_fails(_write(tmp_path, document), "geometry.path: ", "open.stl is not a closed surface")


def test_every_schema_property_has_a_title_and_description():
    def walk(node, where):
        if isinstance(node, dict):
            for name, child in node.get("properties", {}).items():
                if "$ref" not in child:
                    assert child.get("title") and child.get("description"), f"{where}.{name}"
            for key, child in node.items():
                walk(child, f"{where}.{key}")
        elif isinstance(node, list):
            for index, child in enumerate(node):
                walk(child, f"{where}[{index}]")

    schema = load_schema("sensor")
    walk(schema, "schema")
    for name, definition in schema["$defs"].items():
        assert definition.get("title") and definition.get("description"), name
