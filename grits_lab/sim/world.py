"""Builds one scooping world in a fresh PyBullet DIRECT client: table, bowls, Panda with spoon, food particles.

A world is rebuilt from scratch for every episode (fresh client state + the same commands gives
identical states; reusing body ids after removal is unreliable with batch creation). Particles of
each food component are created in one batched `createMultiBody` call with maximal coordinates,
packed in layers inside the source bowl and left to settle before the episode starts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pybullet as pb
import pybullet_data
from pybullet_utils.bullet_client import BulletClient

from grits_lab.sim.bullet import connect_direct
from grits_lab.sim.sim_config import SimConfig
from grits_lab.sim.foods import SampledParticles
from grits_lab.sim.robot import (
    ARM_FORCES,
    ARM_POSITION_GAIN_PER_S,
    ARM_JOINTS,
    FINGER_JOINTS,
    LAST_LINK_ON_TABLE,
    GRASP_LINK,
    PANDA_URDF,
    matrix_to_pose,
    pose_to_matrix,
    spoon_in_hand,
)
from grits_lab.sim.shapes import TARGET_BOWL, Box, BowlGeometry, SpoonGeometry, bowl_boxes, cone_mesh, spoon_boxes

TABLE_HALF = (0.45, 0.6, 0.02)
TABLE_CENTER = (0.45, 0.0, -0.02)
TABLE_TOP = TABLE_CENTER[2] + TABLE_HALF[2]  # world z of the table's top, 0
# How far the bowls' collision floors reach below the table's top: through the table, so that floor
# and table act as one solid support (shapes.bowl_boxes; protocol scoop-v8).
BOWL_SUPPORT_DEPTH = 2 * TABLE_HALF[2]
BOWL_COLOR = (0.92, 0.92, 0.88, 1.0)
TARGET_COLOR = (0.55, 0.75, 0.95, 1.0)
SPOON_COLOR = (0.75, 0.76, 0.8, 1.0)


# Bullet's error reduction parameter for joints and constraints (PyBullet's `erp`; contacts have
# their own, `contactERP`): the share of a constraint's position error corrected in one step, 0.2 by
# Bullet's default, set explicitly so that `ScoopEnv.set_time_step` knows what it ramps back to.
CONSTRAINT_ERP = 0.2

@dataclass
class World:
    """Body ids and geometry of a built world; `client` is the only handle to its simulator."""

    client: BulletClient
    config: SimConfig
    table: int
    source_bowl: list[int]  # the bowl's parts (static bodies sharing one frame)
    target_bowl: list[int]
    robot: int
    spoon: int
    particles: np.ndarray  # (N,) body ids
    particle_components: list[SampledParticles]
    particle_component_index: np.ndarray  # (N,) index into particle_components
    source_bowl_position: np.ndarray  # (3,)
    target_bowl_position: np.ndarray  # (3,)
    source_geometry: BowlGeometry = field(default_factory=BowlGeometry)
    target_geometry: BowlGeometry = TARGET_BOWL
    spoon_geometry: SpoonGeometry = field(default_factory=SpoonGeometry)
    settle_time_s: float = 0.0
    particle_masses: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (N,) kg, as built
    frozen: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))  # (N,) made static by `freeze`
    time_step: float = field(init=False)  # seconds per physics step now: `config.time_step` until `ScoopEnv.set_time_step`

    def __post_init__(self) -> None:
        self.time_step = float(self.config.time_step)

    # ---- state queries -------------------------------------------------------------------
    def particle_positions(self) -> np.ndarray:
        """(N, 3) particle centres, world frame."""
        c = self.client
        return np.array([c.getBasePositionAndOrientation(int(b))[0] for b in self.particles], dtype=np.float64).reshape(-1, 3)

    def particle_speeds(self) -> np.ndarray:
        c = self.client
        v = np.array([c.getBaseVelocity(int(b))[0] for b in self.particles], dtype=np.float64).reshape(-1, 3)
        return np.linalg.norm(v, axis=1)

    def carried_by_spoon(self, through: np.ndarray) -> np.ndarray:
        """(N,) particles the spoon holds through a chain of contacts: touching it, or touching a
        particle it holds, in the contacts of the last physics step. Chains run only through the
        particles `through` (N,) bool (those not lying in a bowl), so a spoon in the source bowl
        does not hold the whole pile. Contacts within Bullet's margin but apart do not count. A grain on the heap's overhang, outside the spoon's
        volume, is held; one falling or lying on the table is not."""
        index = {int(b): i for i, b in enumerate(self.particles)}
        held = np.zeros(len(self.particles), dtype=bool)
        frontier = [int(self.spoon)]
        while frontier:
            for contact in self.client.getContactPoints(bodyA=frontier.pop()):
                if contact[8] > CONTACT_GAP:  # within the contact margin but apart: not touching
                    continue
                i = index.get(int(contact[2]))
                if i is not None and through[i] and not held[i]:
                    held[i] = True
                    frontier.append(int(self.particles[i]))
        return held

    def particle_radii(self) -> np.ndarray:
        """(N,) footprint radius of each particle (see SampledParticles.footprint_radius)."""
        radii = np.array([p.footprint_radius for p in self.particle_components])
        return radii[self.particle_component_index] if len(self.particles) else np.zeros(0)

    def spoon_matrix(self) -> np.ndarray:
        """(4, 4) measured spoon-frame pose (the spoon body's base frame is the spoon frame)."""
        pos, quat = self.client.getBasePositionAndOrientation(self.spoon)
        return pose_to_matrix(np.array(pos), np.array(quat))

    def joint_positions(self) -> np.ndarray:
        return np.array([s[0] for s in self.client.getJointStates(self.robot, list(ARM_JOINTS))])

    def command_joints(self, joints: np.ndarray, velocities: np.ndarray | None = None) -> None:
        """Joint position targets (7,) rad for the arm's motors, with velocity targets (7,) rad/s
        (None: zero, the motors brake towards the target); the position gain is the same per second
        at every time step (`ARM_POSITION_GAIN_PER_S`)."""
        gain = ARM_POSITION_GAIN_PER_S * self.time_step
        self.client.setJointMotorControlArray(
            self.robot, list(ARM_JOINTS), pb.POSITION_CONTROL, targetPositions=[float(q) for q in joints],
            targetVelocities=[0.0] * 7 if velocities is None else [float(v) for v in velocities],
            forces=list(ARM_FORCES), positionGains=[gain] * 7,
        )

    def arm_touches_static(self) -> bool:
        """Whether an arm link (the spoon excluded) is in contact with the table or a bowl now; the
        links up to LAST_LINK_ON_TABLE stand on the table by design."""
        for body in [self.table, *self.source_bowl, *self.target_bowl]:
            for point in self.client.getContactPoints(self.robot, body):
                if body != self.table or point[3] > LAST_LINK_ON_TABLE:
                    return True
        return False

    def freeze(self, mask: np.ndarray) -> None:
        """Make the particles of `mask` (N,) static (mass 0, at rest where they are) and the rest dynamic again."""
        mask = np.asarray(mask, dtype=bool)
        if len(self.frozen) != len(self.particles):
            self.frozen = np.zeros(len(self.particles), dtype=bool)
        for i in np.flatnonzero(mask & ~self.frozen):
            self.client.changeDynamics(int(self.particles[i]), -1, mass=0.0)
        for i in np.flatnonzero(~mask & self.frozen):
            self.client.changeDynamics(int(self.particles[i]), -1, mass=float(self.particle_masses[i]))
        self.frozen = mask.copy()

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.client.stepSimulation()

    def close(self) -> None:
        try:
            self.client.disconnect()
        except pb.error:
            pass


# Contact distance (m) above which Bullet reports two bodies within its contact margin but apart.
CONTACT_GAP = 1e-4
MAX_SHAPES_PER_LINK = 16  # PyBullet silently drops compound children beyond 16


def _compound(client: BulletClient, boxes: list[Box]) -> tuple[int, int]:
    n = len(boxes)
    col = client.createCollisionShapeArray(
        shapeTypes=[pb.GEOM_BOX] * n,
        halfExtents=[list(b.half_extents) for b in boxes],
        collisionFramePositions=[list(b.position) for b in boxes],
        collisionFrameOrientations=[list(b.orientation) for b in boxes],
    )
    vis = client.createVisualShapeArray(
        shapeTypes=[pb.GEOM_BOX] * n,
        halfExtents=[list(b.half_extents) for b in boxes],
        visualFramePositions=[list(b.position) for b in boxes],
        visualFrameOrientations=[list(b.orientation) for b in boxes],
    )  # no rgbaColors here: PyBullet 3.2.7 overruns a buffer with 20+ colours; colour the body instead
    return col, vis


def create_static_boxes(client: BulletClient, boxes: list[Box], position: np.ndarray, color: tuple[float, ...]) -> list[int]:
    """A static object made of many boxes, as rigid bodies of <= 16 boxes each sharing one frame.

    A PyBullet compound shape keeps at most 16 children (extra ones are silently dropped, which
    leaves holes), and static rigid bodies in maximal coordinates collide with particles about
    a third faster than a multibody with welded links.
    """
    bodies = []
    for i in range(0, len(boxes), MAX_SHAPES_PER_LINK):
        col, vis = _compound(client, boxes[i:i + MAX_SHAPES_PER_LINK])
        body = client.createMultiBody(0, col, vis, basePosition=list(map(float, position)), useMaximalCoordinates=True)
        client.changeVisualShape(body, -1, rgbaColor=list(color))
        bodies.append(body)
    return bodies


def _particle_shapes(client: BulletClient, p: SampledParticles) -> tuple[int, int]:
    color = list(p.color)
    if p.shape == "sphere":
        return (client.createCollisionShape(pb.GEOM_SPHERE, radius=p.radius),
                client.createVisualShape(pb.GEOM_SPHERE, radius=p.radius, rgbaColor=color))
    if p.shape == "cube":
        he = [p.radius] * 3
        return (client.createCollisionShape(pb.GEOM_BOX, halfExtents=he),
                client.createVisualShape(pb.GEOM_BOX, halfExtents=he, rgbaColor=color))
    if p.shape == "cylinder":
        return (client.createCollisionShape(pb.GEOM_CYLINDER, radius=p.radius, height=2 * p.half_length),
                client.createVisualShape(pb.GEOM_CYLINDER, radius=p.radius, length=2 * p.half_length, rgbaColor=color))
    verts, faces = cone_mesh(p.radius, p.half_length)
    col = client.createCollisionShape(pb.GEOM_MESH, vertices=verts.tolist())  # convex hull
    vis = client.createVisualShape(pb.GEOM_MESH, vertices=verts.tolist(), indices=faces.reshape(-1).tolist(), rgbaColor=color)
    return col, vis


def _pack_extent(p: SampledParticles) -> tuple[float, float]:
    """(horizontal, vertical) half extents of a packed particle (cylinders and cones lie on their side)."""
    if p.shape == "sphere":
        return p.radius, p.radius
    if p.shape == "cube":
        return p.radius * math.sqrt(2), p.radius
    return math.hypot(p.radius, p.half_length), p.radius


def pack_in_bowl(components: list[SampledParticles], bowl: BowlGeometry, centre: np.ndarray, rng: np.random.Generator,
                 heap_azimuth_deg: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Initial particle centres in layers inside the bowl (world frame) and each slot's component index.

    Slots sit on a jittered square grid, every slot at least one particle clear of the wall, so
    particles start without overlaps and only drop a few millimetres while settling.
    `heap_azimuth_deg` (None: a level fill): only the half of each layer on that side of the bowl's
    axis (world-frame azimuth, degrees from +x) is filled, so the same food stands about twice as
    high against one wall and slumps towards the other while settling (`SimConfig.heap_azimuth_deg`).
    """
    if not components:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    extents = [_pack_extent(p) for p in components]
    h = max(e[0] for e in extents) * 1.08
    v = max(e[1] for e in extents) * 1.08
    total = sum(p.count for p in components)
    side = None if heap_azimuth_deg is None else np.array([math.cos(math.radians(heap_azimuth_deg)), math.sin(math.radians(heap_azimuth_deg))])
    slots: list[np.ndarray] = []
    z = bowl.floor_thickness + v + 0.0005
    layer = 0
    while len(slots) < total:
        r_avail = float(bowl.inner_radius_at(z - v)) - h - 0.002
        if z > bowl.depth:
            r_avail = bowl.rim_radius - h - 0.004
        offset = rng.uniform(-0.5, 0.5, size=2) * h
        n = int(math.ceil(r_avail / (2 * h))) + 1
        grid = [np.array([i * 2 * h, j * 2 * h]) + offset for i in range(-n, n + 1) for j in range(-n, n + 1)]
        ring = [g for g in grid if np.linalg.norm(g) <= r_avail and (side is None or float(g @ side) >= 0.0)]
        rng.shuffle(ring)
        for g in ring:
            if len(slots) == total:
                break
            slots.append(np.array([g[0], g[1], z]))
        z += 2 * v + 0.0008
        layer += 1
        if layer > 200:
            raise ValueError("particles do not fit into the bowl")
    positions = np.array(slots)
    positions[:, :2] += rng.uniform(-0.1, 0.1, size=(total, 2)) * (h - max(e[0] for e in extents) * 0.95 + 1e-4)
    order = rng.permutation(total)
    comp_index = np.concatenate([np.full(p.count, i) for i, p in enumerate(components)])[order]
    return positions + centre, comp_index


def build_static_scene(client: BulletClient, source_position: np.ndarray, target_position: np.ndarray) -> tuple[int, list[int], list[int]]:
    """The table, the source bowl's and the target bowl's bodies (static) in `client`, the bowls at
    (3,) positions: the world's own, and the same obstacles on the arm's kinematic copy, where paths
    are checked against them."""
    table = client.createMultiBody(
        0, client.createCollisionShape(pb.GEOM_BOX, halfExtents=TABLE_HALF),
        client.createVisualShape(pb.GEOM_BOX, halfExtents=TABLE_HALF, rgbaColor=[0.6, 0.45, 0.3, 1]),
        basePosition=TABLE_CENTER,
    )
    source_bowl = create_static_boxes(client, bowl_boxes(BowlGeometry(), BOWL_SUPPORT_DEPTH), source_position, BOWL_COLOR)
    target_bowl = create_static_boxes(client, bowl_boxes(TARGET_BOWL, BOWL_SUPPORT_DEPTH), target_position, TARGET_COLOR)
    return table, source_bowl, target_bowl


def apply_physics(client: BulletClient, config: SimConfig) -> None:
    """The world's physics settings in `client`: time step, solver iterations, contact breaking
    threshold, deterministic pairs, the constraints' error reduction (`CONSTRAINT_ERP`), gravity (SimConfig)."""
    client.setPhysicsEngineParameter(
        fixedTimeStep=config.time_step, numSolverIterations=config.solver_iterations, numSubSteps=0,
        deterministicOverlappingPairs=1, contactBreakingThreshold=config.contact_breaking_threshold, erp=CONSTRAINT_ERP,
    )
    client.setGravity(0, 0, -9.81)


def build_world(config: SimConfig, components: list[SampledParticles], rng: np.random.Generator,
                target_xy: tuple[float, float], joints: np.ndarray | None = None) -> World:
    """Create the client and every body; the arm starts at `joints` (7,), particles still unsettled."""
    client = connect_direct()
    client.setAdditionalSearchPath(pybullet_data.getDataPath())
    apply_physics(client, config)

    source_geometry, target_geometry, spoon_geometry = BowlGeometry(), TARGET_BOWL, SpoonGeometry()
    src_pos = np.array([config.source_bowl_xy[0], config.source_bowl_xy[1], 0.0])
    tgt_pos = np.array([target_xy[0], target_xy[1], 0.0])
    table, source_bowl, target_bowl = build_static_scene(client, src_pos, tgt_pos)

    robot = client.loadURDF(PANDA_URDF, [0, 0, 0], useFixedBase=True)
    if joints is not None:
        for j, q in zip(ARM_JOINTS, joints):
            client.resetJointState(robot, j, float(q))
    for j in FINGER_JOINTS:
        client.resetJointState(robot, j, 0.006)
    client.setJointMotorControlArray(robot, list(FINGER_JOINTS), pb.POSITION_CONTROL, targetPositions=[0.006, 0.006], forces=[20, 20])
    state = client.getLinkState(robot, GRASP_LINK, computeForwardKinematics=True)
    hand = pose_to_matrix(np.array(state[4]), np.array(state[5]))
    hand_in_spoon = spoon_in_hand(spoon_geometry)
    spoon_pose = hand @ np.linalg.inv(hand_in_spoon)
    pos, quat = matrix_to_pose(spoon_pose)
    boxes = spoon_boxes(spoon_geometry)
    assert len(boxes) <= MAX_SHAPES_PER_LINK, "the spoon must be one compound of at most 16 boxes"
    col, vis = _compound(client, boxes)
    spoon = client.createMultiBody(config.spoon_mass, col, vis, basePosition=pos.tolist(), baseOrientation=quat.tolist())
    client.changeVisualShape(spoon, -1, rgbaColor=list(SPOON_COLOR))
    _, hq = matrix_to_pose(hand_in_spoon)
    cid = client.createConstraint(robot, GRASP_LINK, spoon, -1, pb.JOINT_FIXED, [0, 0, 0], [0, 0, 0],
                                  hand_in_spoon[:3, 3].tolist(), [0, 0, 0, 1], hq.tolist())
    client.changeConstraint(cid, maxForce=2000)
    for link in range(-1, client.getNumJoints(robot)):
        client.setCollisionFilterPair(robot, spoon, link, -1, 0)
        client.setCollisionFilterPair(robot, table, link, -1, 0 if link <= LAST_LINK_ON_TABLE else 1)

    ids, comp_of, masses = [], [], []
    positions, comp_index = pack_in_bowl(components, source_geometry, src_pos, rng, config.heap_azimuth_deg)
    for ci, p in enumerate(components):
        mask = comp_index == ci
        col, vis = _particle_shapes(client, p)
        orient = [0, 0, 0, 1] if p.shape in ("sphere", "cube") else list(pb.getQuaternionFromEuler([math.pi / 2, 0, 0]))
        batch = client.createMultiBody(
            baseMass=float(p.mass.mean()), baseCollisionShapeIndex=col, baseVisualShapeIndex=vis,
            basePosition=[0, 0, 0], baseOrientation=orient, batchPositions=positions[mask].tolist(), useMaximalCoordinates=True,
        )
        batch = [batch] if isinstance(batch, int) else list(batch)
        yaws = rng.uniform(0, 2 * math.pi, size=len(batch))
        for k, body in enumerate(batch):
            kwargs = dict(mass=float(p.mass[k]), lateralFriction=float(p.lateral_friction[k]),
                          rollingFriction=float(p.rolling_friction[k]), spinningFriction=float(p.spinning_friction[k]),
                          restitution=float(p.restitution[k]))
            if p.contact_stiffness is not None:
                kwargs.update(contactStiffness=p.contact_stiffness, contactDamping=p.contact_damping)
            client.changeDynamics(body, -1, **kwargs)
            if p.shape != "sphere":
                q = pb.getQuaternionFromEuler([math.pi / 2 if p.shape != "cube" else 0.0, 0.0, float(yaws[k])])
                client.resetBasePositionAndOrientation(body, positions[mask][k].tolist(), q)
        ids.extend(batch)
        comp_of.extend([ci] * len(batch))
        masses.extend(float(m) for m in p.mass[: len(batch)])
    return World(
        client=client, config=config, table=table, source_bowl=source_bowl, target_bowl=target_bowl, robot=robot,
        spoon=spoon, particles=np.array(ids, dtype=np.int64), particle_components=components,
        particle_component_index=np.array(comp_of, dtype=np.int64), source_bowl_position=src_pos,
        target_bowl_position=tgt_pos, source_geometry=source_geometry, target_geometry=target_geometry,
        spoon_geometry=spoon_geometry, particle_masses=np.array(masses, dtype=np.float64),
        frozen=np.zeros(len(ids), dtype=bool),
    )


def settle(world: World) -> float:
    """Step until every particle is slower than `settle_speed` (after `settle_min_s`); returns sim seconds."""
    cfg = world.config
    chunk = max(1, int(round(0.05 / cfg.time_step)))
    steps, max_steps, min_steps = 0, int(cfg.settle_max_s / cfg.time_step), int(cfg.settle_min_s / cfg.time_step)
    while steps < max_steps:
        world.step(chunk)
        steps += chunk
        if steps >= min_steps and (len(world.particles) == 0 or world.particle_speeds().max() < cfg.settle_speed):
            break
    world.settle_time_s = steps * cfg.time_step
    return world.settle_time_s
