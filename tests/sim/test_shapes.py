"""Bowl and spoon geometry: really concave, closed (no seams a particle fits through), meshes up to date."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pybullet as pb
import pytest

from grits_lab.sim.shapes import TARGET_BOWL, BowlGeometry, SpoonGeometry, bowl_boxes, boxes_to_mesh, spoon_boxes
from grits_lab.sim.bullet import connect_direct
from grits_lab.sim.world import MAX_SHAPES_PER_LINK, _compound, create_static_boxes

ASSETS = Path(__file__).resolve().parents[2] / "assets"


@pytest.fixture(scope="module")
def client():
    c = connect_direct()
    yield c
    c.disconnect()


@pytest.mark.parametrize("geometry", [BowlGeometry(), TARGET_BOWL], ids=["source", "target"])
def test_bowl_is_closed_and_concave(client, geometry):
    client.resetSimulation()
    create_static_boxes(client, bowl_boxes(geometry), np.zeros(3), (1, 1, 1, 1))
    # Horizontal rays from the axis outwards, every 2 degrees at many heights, all hit the wall...
    starts, ends = [], []
    for z in np.linspace(geometry.floor_thickness + 0.002, geometry.depth - 0.002, 15):
        for th in np.linspace(0, 2 * math.pi, 180, endpoint=False):
            starts.append([0, 0, z])
            ends.append([0.3 * math.cos(th), 0.3 * math.sin(th), z])
    hits = client.rayTestBatch(starts, ends)
    assert all(h[0] >= 0 for h in hits)
    radial = np.array([np.linalg.norm(h[3][:2]) for h in hits])
    assert radial.max() <= geometry.rim_radius + 1e-3 and radial.min() >= geometry.floor_radius - 1e-3
    # ...and vertical rays inside the floor radius land on the floor.
    grid = [(x, y) for x in np.linspace(-1, 1, 15) for y in np.linspace(-1, 1, 15) if x * x + y * y <= 1]
    r = geometry.floor_radius
    hits = client.rayTestBatch([[r * x, r * y, 0.2] for x, y in grid], [[r * x, r * y, -0.1] for x, y in grid])
    assert all(h[0] >= 0 and abs(h[3][2] - geometry.floor_thickness) < 1e-4 for h in hits)


def test_source_bowl_dimensions_match_the_paper():
    g = BowlGeometry()
    assert 0.16 <= 2 * g.outer_radius <= 0.18 and g.depth == pytest.approx(0.065)


def test_spoon_is_one_compound_with_a_concave_bowl(client):
    g = SpoonGeometry()
    boxes = spoon_boxes(g)
    assert len(boxes) <= MAX_SHAPES_PER_LINK
    bowl_vertices, _ = boxes_to_mesh(boxes[:-1])  # the last box is the handle
    length, width = np.ptp(bowl_vertices[:, 0]), np.ptp(bowl_vertices[:, 1])
    assert 0.05 <= length <= 0.07 and 0.035 <= width <= 0.055, (length, width)  # about 4 x 6 cm
    client.resetSimulation()
    col, vis = _compound(client, boxes)
    client.createMultiBody(0, col, vis)
    # Rays from the centre towards the sides and the back hit the rim above the floor: it holds food.
    starts = [[0, 0, 0.003]] * 3
    ends = [[0, 0.06, 0.003], [0, -0.06, 0.003], [-0.07, 0, 0.003]]
    hits = client.rayTestBatch(starts, ends)
    assert all(h[0] >= 0 for h in hits)
    assert abs(hits[0][3][1]) < g.half_width + 0.006 and abs(hits[2][3][0]) < g.half_length + 0.008
    # The floor lies under the whole bowl ellipse.
    down = client.rayTestBatch([[0.9 * g.half_length * c, 0.9 * g.half_width * s, 0.05] for c, s in ((1, 0), (0, 1), (-0.7, 0.7), (0, 0))],
                               [[0.9 * g.half_length * c, 0.9 * g.half_width * s, -0.05] for c, s in ((1, 0), (0, 1), (-0.7, 0.7), (0, 0))])
    assert all(h[0] >= 0 and abs(h[3][2]) < 1e-4 for h in down)


@pytest.mark.parametrize("name, boxes", [("spoon.obj", spoon_boxes(SpoonGeometry())), ("source_bowl.obj", bowl_boxes(BowlGeometry())),
                                         ("target_bowl.obj", bowl_boxes(TARGET_BOWL))])
def test_asset_meshes_match_the_simulated_geometry(name, boxes):
    vertices, faces = boxes_to_mesh(boxes)
    lines = (ASSETS / name).read_text().splitlines()
    stored_v = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("v ")])
    stored_f = np.array([[int(x) - 1 for x in ln.split()[1:]] for ln in lines if ln.startswith("f ")])
    assert stored_v.shape == vertices.shape, "regenerate with `python assets/make_assets.py`"
    assert np.allclose(stored_v, vertices, atol=2e-6) and np.array_equal(stored_f, faces)


def _discs_below_table(support_depth: float) -> int:
    """40 mentos-sized discs (r 8.25 mm, 7.5 mm thick, 2.75 g) dropped 12-20 cm into the target
    bowl on the table, at the world's physics settings; how many end with their centre below the
    table's top after 3 s."""
    from grits_lab.sim.sim_config import SimConfig
    from grits_lab.sim.world import TABLE_CENTER, TABLE_HALF, TABLE_TOP, apply_physics

    cfg = SimConfig()
    c = connect_direct()
    try:
        apply_physics(c, cfg)
        centre = np.array([TABLE_CENTER[0], TABLE_CENTER[1], TABLE_TOP])
        create_static_boxes(c, bowl_boxes(TARGET_BOWL, support_depth), centre, (1, 1, 1, 1))
        c.createMultiBody(0, c.createCollisionShape(pb.GEOM_BOX, halfExtents=TABLE_HALF), -1, basePosition=TABLE_CENTER)
        disc = c.createCollisionShape(pb.GEOM_CYLINDER, radius=0.00825, height=0.0075)
        rng = np.random.default_rng(0)
        bodies = []
        for k in range(40):
            x, y = rng.uniform(-0.025, 0.025, 2)
            q = pb.getQuaternionFromEuler(rng.uniform(-0.6, 0.6, 3).tolist())
            b = c.createMultiBody(0.00275, disc, -1, basePosition=(centre + [x, y, 0.12 + 0.012 * (k % 8)]).tolist(), baseOrientation=q)
            c.changeDynamics(b, -1, lateralFriction=0.35, rollingFriction=0.0015, spinningFriction=0.0015, restitution=0.15)
            bodies.append(b)
        for _ in range(int(round(3.0 / cfg.time_step))):
            c.stepSimulation()
        z = np.array([c.getBasePositionAndOrientation(b)[0][2] for b in bodies])
        return int((z < TABLE_TOP).sum())
    finally:
        c.disconnect()


def test_a_floor_through_the_table_holds_dropped_discs():
    from grits_lab.sim.world import BOWL_SUPPORT_DEPTH, TABLE_HALF

    assert BOWL_SUPPORT_DEPTH == pytest.approx(2 * TABLE_HALF[2])
    # The world's floors: no disc passes through.
    assert _discs_below_table(BOWL_SUPPORT_DEPTH) == 0
    # The 6 mm floor alone (scoop-v7 and earlier) lets many through: the case the support fixes.
    assert _discs_below_table(0.0) >= 5


def test_the_support_extends_only_the_floor_downwards():
    plain, supported = bowl_boxes(BowlGeometry()), bowl_boxes(BowlGeometry(), 0.04)
    assert len(plain) == len(supported)
    for a, b in zip(plain, supported):
        top_a = a.position[2] + a.half_extents[2]
        top_b = b.position[2] + b.half_extents[2]
        if a == b:
            continue  # walls are unchanged
        assert top_b == pytest.approx(top_a) == pytest.approx(BowlGeometry().floor_thickness)
        assert b.position[2] - b.half_extents[2] == pytest.approx(-0.04)
    assert sum(a != b for a, b in zip(plain, supported)) == 7  # the floor's strips
    with pytest.raises(ValueError, match="support_depth"):
        bowl_boxes(BowlGeometry(), -0.01)


def test_the_spoon_holds_a_grain_stacked_on_its_load_and_not_one_on_the_table():
    """`World.carried_by_spoon`: contact chains from the spoon, through the allowed particles only."""
    from grits_lab.sim import ScoopEnv
    from grits_lab.sim.spill_metrics import in_spoon_frame

    env = ScoopEnv()
    try:
        env.reset(seed=0, options={"food": "chocolate_balls", "level": "low"})
        world = env.world
        spoon = world.spoon_matrix()
        r = float(world.particle_radii()[0])
        # The spoon rests at home above the table; put grain 0 on its floor, grain 1 on grain 0,
        # grain 2 on the table far from everything.
        floor = spoon[:3, 3] + spoon[:3, 2] * (world.spoon_geometry.thickness / 2 + r)
        places = [floor, floor + spoon[:3, 2] * 2 * r, np.array([0.3, -0.4, r])]
        for body, place in zip(world.particles[:3], places):
            world.client.resetBasePositionAndOrientation(int(body), place.tolist(), [0, 0, 0, 1])
            world.client.resetBaseVelocity(int(body), [0, 0, 0], [0, 0, 0])
        world.step(5)  # contacts are those of the last physics step
        assert in_spoon_frame(world.particle_positions()[:2], world.spoon_matrix())[:, 2].min() > 0  # still on the spoon
        every = np.ones(len(world.particles), dtype=bool)
        held = world.carried_by_spoon(through=every)
        assert held[:3].tolist() == [True, True, False]
        through = every.copy()
        through[0] = False  # chains may not run through grain 0: grain 1 only touches grain 0
        assert world.carried_by_spoon(through=through)[:3].tolist() == [False, False, False]
    finally:
        env.close()
