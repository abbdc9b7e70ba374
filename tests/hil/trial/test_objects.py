"""The ten objects of the arrays (``hil.trial.objects``) and the shapes they are made of
(``ObjectConfig.shape``): each compiles with its stated mass, rests on the floor at the height its geometry
says (so its size and orientation are what the table says), and a bad shape is refused in one line."""

from __future__ import annotations

import math
from dataclasses import replace

import mujoco
import numpy as np
import pytest

from hil.sim.config import DroneConfig, ModelConfig, ObjectConfig
from hil.sim.object_shapes import CONE_SIDES, object_mesh_vertices
from hil.sim.plant import Plant
from hil.sim.types import PlantConfig
from hil.trial.objects import ARRAY_OBJECTS, ArrayObject, stone_vertices

S = 1_000_000
_SQUARE = ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))


def _rest_height_m(o: ArrayObject) -> float:
    """How high above the floor the object's frame rests, from its geometry alone."""
    c = o.config
    up = abs(c.axis[2]) / math.sqrt(sum(v * v for v in c.axis)) > 0.5
    if c.shape == "sphere":
        return c.radius_m
    if c.shape == "cone":
        return 0.5 * c.length_m  # on its base: the apex up (+axis)
    if up:  # standing on an end face
        return 0.5 * c.length_m
    return c.radius_m  # lying on its side


@pytest.mark.parametrize("obj", ARRAY_OBJECTS, ids=lambda o: o.key)
def test_each_object_has_its_mass_and_rests_on_the_floor_at_its_geometrys_height(obj: ArrayObject) -> None:
    model = ModelConfig(drone=DroneConfig(floor=True), objects=(obj.placed((0.5, 0.0, 0.2)),))
    plant = Plant(config=PlantConfig(model=model))
    m = plant.mj_model
    body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, obj.config.name)
    assert m.body_mass[body] == pytest.approx(obj.config.mass_kg, rel=1e-6)
    plant.run(S)  # falls 0.2 m and settles
    pose = plant.object_pose(obj.config.name)
    speed = np.linalg.norm(plant.mj_data.qvel[-6:-3])
    assert speed < 0.02, speed
    if obj.config.shape == "mesh":
        # An irregular stone rolls onto a stable face: its hull's lowest point (MuJoCo's own vertices,
        # placed by its geom's pose) is on the floor.
        geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{obj.config.name}_geom")
        mesh = int(m.geom_dataid[geom])
        start, n = int(m.mesh_vertadr[mesh]), int(m.mesh_vertnum[mesh])
        d = plant.mj_data
        world = d.geom_xpos[geom] + m.mesh_vert[start : start + n] @ d.geom_xmat[geom].reshape(3, 3).T
        assert world[:, 2].min() == pytest.approx(0.0, abs=1.5e-3)
        assert n >= 4
        return
    # The frame's height: the geometry's (a contact's few tenths of a mm of penetration aside).
    assert pose.pos_m[2] == pytest.approx(_rest_height_m(obj), abs=1.5e-3), obj.key
    # It landed the way the table says it stands or lies: its geom's z axis still along the stated axis.
    geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{obj.config.name}_geom")
    z = plant.mj_data.geom_xmat[geom].reshape(3, 3)[:, 2]
    axis = np.asarray(obj.config.axis) / np.linalg.norm(obj.config.axis)
    assert abs(float(z @ axis)) > 0.99 or obj.config.shape in ("sphere", "mesh"), (obj.key, z)


def test_the_catalogue_spans_shapes_sizes_and_masses() -> None:
    keys = [o.key for o in ARRAY_OBJECTS]
    assert len(keys) == 10 and len(set(keys)) == 10
    assert {o.config.shape for o in ARRAY_OBJECTS} == {
        "sphere",
        "box",
        "cylinder",
        "cone",
        "ellipsoid",
        "mesh",
    }
    assert all(o.what and o.why and 0 < o.config.friction <= 1 for o in ARRAY_OBJECTS)
    sizes = sorted(o.size_m for o in ARRAY_OBJECTS)
    assert sizes[0] == pytest.approx(0.025) and sizes[-1] == pytest.approx(0.2, rel=0.01)
    masses = [o.config.mass_kg for o in ARRAY_OBJECTS]
    assert min(masses) == 0.010 and max(masses) == 0.070  # type: ignore[type-var]


def test_a_cone_is_a_pyramid_of_its_radius_and_height() -> None:
    cone = ObjectConfig("c", 0.03, 0.08, (0, 0, 0), shape="cone")
    v = np.asarray(object_mesh_vertices(cone))
    assert len(v) == CONE_SIDES + 1
    assert np.allclose(np.hypot(v[:-1, 0], v[:-1, 1]), 0.03) and np.allclose(v[:-1, 2], -0.04)
    assert tuple(v[-1]) == (0.0, 0.0, 0.04)
    assert object_mesh_vertices(replace(cone, shape="sphere")) == ()


def test_the_stone_is_seeded_and_irregular() -> None:
    a, b = stone_vertices(0.03), stone_vertices(0.03)
    assert a == b and stone_vertices(0.03, seed=8) != a
    r = np.linalg.norm(np.asarray(a), axis=1)
    assert 0.015 < r.min() < r.max() < 0.05 and r.std() > 0.002


@pytest.mark.parametrize(
    ("obj", "says"),
    [
        (ObjectConfig("o", 0.01, 0.1, (0, 0, 0), shape="torus"), "shape must be one of"),
        (ObjectConfig("o", 0.01, 0.1, (0, 0, 0), shape="mesh"), "4 to 1000 vertices"),
        (
            ObjectConfig(
                "o", 0.01, 0.1, (0, 0, 0), shape="mesh", vertices=((0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0))
            ),
            "one plane",
        ),
        (
            ObjectConfig(
                "o",
                0.01,
                0.1,
                (0, 0, 0),
                shape="mesh",
                vertices=((0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, math.nan)),
            ),
            "vertices",
        ),
        (ObjectConfig("o", 0.01, 0.1, (0, 0, 0), vertices=((0, 0, 0),) * 4), "vertices are for a mesh"),
    ],
)
def test_bad_shapes_are_refused_in_one_line(obj: ObjectConfig, says: str) -> None:
    with pytest.raises(ValueError, match=says):
        obj.validate()


def test_the_plant_docs_table_is_the_catalogue() -> None:
    from pathlib import Path

    text = (Path(__file__).resolve().parents[3] / "docs" / "plant.md").read_text()
    for o in ARRAY_OBJECTS:
        row = next(line for line in text.splitlines() if line.startswith(f"| `{o.key}` |"))
        assert o.what in row and f"{o.config.mass_kg * 1000:g} g" in row and o.why in row, row  # type: ignore[operator]
