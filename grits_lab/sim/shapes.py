"""Geometry of the bowls and the spoon: box decompositions for collision and triangle meshes for CAD points.

Both the simulator and `assets/make_assets.py` build from these functions, so the collision
geometry, the rendered geometry and the meshes the perception code samples points from are one
and the same. Everything is pure numpy (no simulator state).

Frames:
- A bowl's frame has its origin at the centre of the bowl's outer bottom (resting on the table),
  z up. The inner floor is at z = `floor_thickness`, the rim at z = `depth`.
- The spoon frame (the tool frame of every 9-D action) has its origin at the centre of the
  spoon bowl's inner floor surface; x points to the spoon's tip, z along the bowl's normal (the
  side that holds food), y = z x x. The handle leaves the back of the bowl (negative x) and rises
  at `handle_elevation_deg` to the grasp point where the robot hand holds it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Box:
    """A box part of a compound shape: half extents, centre and orientation (quaternion xyzw)."""

    half_extents: tuple[float, float, float]
    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float]


@dataclass(frozen=True)
class BowlGeometry:
    """A round bowl shaped as a truncated cone: flat floor and slanted walls.

    Defaults: the source bowl of the authors' scene, about 17 cm across at the rim and 6.5 cm deep.
    """

    floor_radius: float = 0.035  # inner radius at the floor
    rim_radius: float = 0.080  # inner radius at the rim
    depth: float = 0.065  # outer height: table to rim
    wall_thickness: float = 0.006
    floor_thickness: float = 0.006
    segments: int = 24  # wall segments around the circle

    @property
    def outer_radius(self) -> float:
        slant = self.slant_angle
        return self.rim_radius + self.wall_thickness / math.cos(slant)

    @property
    def slant_angle(self) -> float:
        """Angle of the walls from the vertical (radians)."""
        return math.atan2(self.rim_radius - self.floor_radius, self.depth - self.floor_thickness)

    def inner_radius_at(self, z: np.ndarray | float) -> np.ndarray | float:
        """Inner radius of the bowl at height z (bowl frame), clipped to [floor, rim]."""
        t = np.clip((np.asarray(z) - self.floor_thickness) / (self.depth - self.floor_thickness), 0.0, 1.0)
        return self.floor_radius + t * (self.rim_radius - self.floor_radius)


# The target bowl: smaller and shallower than the source bowl (about 12 cm across, 4.5 cm deep).
TARGET_BOWL = BowlGeometry(floor_radius=0.038, rim_radius=0.058, depth=0.045, segments=20)


@dataclass(frozen=True)
class SpoonGeometry:
    """A spoon with an elliptical, concave bowl (about 4 x 6 cm) and a straight handle."""

    half_length: float = 0.025  # inner floor semi-axis along x (with the rim: about 6 cm long)
    half_width: float = 0.016  # inner floor semi-axis along y (with the rim: about 4 cm wide)
    wall_height: float = 0.014  # slant length of the bowl's rim wall at the back and sides
    lip_height: float = 0.0  # slant length at the tip: no lip, so the thin edge slides under food
    wall_slant_deg: float = 45.0  # rim wall leaning outwards from the normal (a low, open lip)
    thickness: float = 0.002
    segments: int = 10  # with 5 floor strips and the handle: 16 boxes, one PyBullet compound
    handle_length: float = 0.12
    handle_elevation_deg: float = 70.0  # handle rises steeply (like a ladle) so it clears the bowl rim
    handle_width: float = 0.012
    handle_thickness: float = 0.004

    @property
    def bowl_area(self) -> float:
        """Area of the elliptical floor (m^2): the denominator of the spoon coverage fraction."""
        return math.pi * self.half_length * self.half_width

    @property
    def rim_height(self) -> float:
        return self.wall_height * math.cos(math.radians(self.wall_slant_deg))

    def grasp_point(self) -> np.ndarray:
        """The handle's far end (spoon frame), where the hand's grasp frame sits."""
        e = math.radians(self.handle_elevation_deg)
        start = np.array([-self.half_length - 0.004, 0.0, self.rim_height * 0.5])
        return start + self.handle_length * np.array([-math.cos(e), 0.0, math.sin(e)])

    def pour_edge(self, axis: str) -> float:
        """Metres from the spoon's centre to the edge food leaves by when poured: the top of the side
        wall (its -y lip) for a roll about x, the tip (+x, a lip of only the wall's thickness) for a
        turn about the tip."""
        if axis == "roll":
            return self.half_width + self.wall_height * math.sin(math.radians(self.wall_slant_deg))
        return self.half_length + self.thickness

    def hand_from_spoon_rotation(self) -> np.ndarray:
        """(3, 3) rotation of the hand's grasp frame expressed in the spoon frame.

        The hand's approach axis (z) runs along the handle towards the spoon bowl, its finger axis
        (y) across the handle, so the gripper pinches the handle like a pen.
        """
        e = math.radians(self.handle_elevation_deg)
        z = np.array([math.cos(e), 0.0, -math.sin(e)])
        y = np.array([0.0, -1.0, 0.0])  # with z forward-down this is the Panda's natural wrist roll
        x = np.cross(y, z)
        return np.stack([x, y, z], axis=1)


def _quat_from_matrix(m: np.ndarray) -> tuple[float, float, float, float]:
    from grits_lab.geometry import matrix_to_quat

    q = matrix_to_quat(m)
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_y(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _ellipse_strips(half_x: float, half_y: float, thickness: float, z: float, strips: int) -> list[Box]:
    """Flat boxes (strips along x) covering an ellipse; each strip is as long as the ellipse at its inner edge."""
    boxes = []
    for j in range(strips):
        y0 = -half_y + 2 * half_y * j / strips
        y1 = y0 + 2 * half_y / strips
        y_inner = min(abs(y0), abs(y1)) if y0 * y1 > 0 else 0.0
        hx = half_x * math.sqrt(max(0.0, 1 - (y_inner / half_y) ** 2))
        boxes.append(Box((hx, (y1 - y0) / 2 * 1.02, thickness / 2), (0.0, (y0 + y1) / 2, z), (0.0, 0.0, 0.0, 1.0)))
    return boxes


def bowl_boxes(g: BowlGeometry, support_depth: float = 0.0) -> list[Box]:
    """Boxes whose union is the bowl: a floor of 7 strips and slanted wall segments.

    The wall boxes reach below the floor's top and overlap their neighbours at the outer face, so
    no seam is wide enough for a particle to leak through.

    `support_depth` (m, >= 0) extends the floor's boxes that far below the bowl's bottom (z = 0),
    into the table it stands on; the inner floor stays at z = `floor_thickness`. The simulator's
    collision bowls use the table's thickness (world.BOWL_SUPPORT_DEPTH): Bullet resolves a deep
    contact towards the nearer face of a box, so a disc pressed more than half way into a 6 mm
    floor was pushed out through its underside and sank (docs/sim.md, "Floors that hold"). The
    bowl's own shape (assets/, the perception's CAD points) keeps the default 0.

    Raises:
        ValueError: `support_depth` < 0.
    """
    if support_depth < 0:
        raise ValueError(f"support_depth must be >= 0 metres, got {support_depth}")
    boxes: list[Box] = []
    floor_height = g.floor_thickness + support_depth
    boxes += _ellipse_strips(g.floor_radius + g.wall_thickness * 0.6, g.floor_radius + g.wall_thickness * 0.6,
                             floor_height, g.floor_thickness - floor_height / 2, strips=7)
    a = g.slant_angle
    wall_len = math.hypot(g.rim_radius - g.floor_radius, g.depth - g.floor_thickness)
    extra = g.floor_thickness  # reach into the floor
    length = wall_len + extra
    outer_top = g.rim_radius + g.wall_thickness
    width = 2 * outer_top * math.tan(math.pi / g.segments) * 1.08
    up = np.array([math.sin(a), math.cos(a)])  # (r, z) direction along the wall, upwards
    normal = np.array([math.cos(a), -math.sin(a)])  # outward normal in (r, z)
    mid_inner = np.array([(g.floor_radius + g.rim_radius) / 2, (g.floor_thickness + g.depth) / 2])
    centre_rz = mid_inner + normal * g.wall_thickness / 2 - up * extra / 2
    for k in range(g.segments):
        phi = 2 * math.pi * k / g.segments
        # Local box axes: x = outward normal, y = tangent, z = along the wall; tilt about y by the slant.
        rot = _rot_z(phi) @ _rot_y(a)
        pos = (centre_rz[0] * math.cos(phi), centre_rz[0] * math.sin(phi), centre_rz[1])
        boxes.append(Box((g.wall_thickness / 2, width / 2, length / 2), pos, _quat_from_matrix(rot)))
    return boxes


def spoon_boxes(g: SpoonGeometry) -> list[Box]:
    """Boxes whose union is the spoon: floor strips, a slanted rim wall around the ellipse, the handle."""
    boxes: list[Box] = []
    t = g.thickness
    boxes += _ellipse_strips(g.half_length + t, g.half_width + t, t, -t / 2, strips=5)
    slant = math.radians(g.wall_slant_deg)
    extra = t
    for k in range(g.segments):
        th0 = 2 * math.pi * k / g.segments
        th1 = 2 * math.pi * (k + 1) / g.segments
        thm = (th0 + th1) / 2
        # The rim is lowest at the tip (+x) and rises to full height at the sides and back.
        height = g.wall_height - (g.wall_height - g.lip_height) * max(0.0, math.cos(thm)) ** 2
        length = height + extra
        p0 = np.array([g.half_length * math.cos(th0), g.half_width * math.sin(th0)])
        p1 = np.array([g.half_length * math.cos(th1), g.half_width * math.sin(th1)])
        pm = np.array([g.half_length * math.cos(thm), g.half_width * math.sin(thm)])
        chord = np.linalg.norm(p1 - p0)
        normal = np.array([math.cos(thm) / g.half_length, math.sin(thm) / g.half_width])
        normal /= np.linalg.norm(normal)
        yaw = math.atan2(normal[1], normal[0])
        rot = _rot_z(yaw) @ _rot_y(slant)
        up = np.array([normal[0] * math.sin(slant), normal[1] * math.sin(slant), math.cos(slant)])
        out = np.array([normal[0] * math.cos(slant), normal[1] * math.cos(slant), -math.sin(slant)])
        centre = np.array([pm[0], pm[1], 0.0]) + up * (height - extra) / 2 + out * t / 2
        width = chord * 1.25 + t
        boxes.append(Box((t / 2, width / 2, length / 2), tuple(centre), _quat_from_matrix(rot)))
    e = math.radians(g.handle_elevation_deg)
    start = np.array([-g.half_length - 0.004, 0.0, g.rim_height * 0.5])
    direction = np.array([-math.cos(e), 0.0, math.sin(e)])
    centre = start + direction * g.handle_length / 2
    rot = _rot_y(e - math.pi)  # box x axis along the handle: (-cos e, 0, sin e), back and up
    boxes.append(Box((g.handle_length / 2 + 0.006, g.handle_width / 2, g.handle_thickness / 2), tuple(centre), _quat_from_matrix(rot)))
    return boxes


def boxes_to_mesh(boxes: list[Box]) -> tuple[np.ndarray, np.ndarray]:
    """Triangle mesh (vertices (V, 3), faces (F, 3)) of the union's boundary boxes (not merged)."""
    from grits_lab.geometry import quat_to_matrix

    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    verts, faces = [], []
    for i, b in enumerate(boxes):
        r = quat_to_matrix(np.array(b.orientation))
        v = (corners * np.array(b.half_extents)) @ r.T + np.array(b.position)
        verts.append(v)
        base = 8 * i
        for q in quads:
            faces.append((base + q[0], base + q[1], base + q[2]))
            faces.append((base + q[0], base + q[2], base + q[3]))
    return np.concatenate(verts), np.array(faces, dtype=np.int64)


def write_obj(path: str, vertices: np.ndarray, faces: np.ndarray, comment: str = "") -> None:
    """Write a Wavefront OBJ (1-based faces); `comment` lines document the frame."""
    from grits_lab.io import write_text_atomic

    lines = [f"# {line}" for line in comment.splitlines()]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    write_text_atomic(path, "\n".join(lines) + "\n")


def cone_mesh(radius: float, half_height: float, sides: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A cone along z centred on its bounding box (apex at +half_height): vertices and faces."""
    angles = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.stack([radius * np.cos(angles), radius * np.sin(angles), np.full(sides, -half_height)], axis=1)
    verts = np.concatenate([ring, [[0, 0, half_height]], [[0, 0, -half_height]]])
    apex, bottom = sides, sides + 1
    faces = []
    for i in range(sides):
        j = (i + 1) % sides
        faces.append((i, j, apex))
        faces.append((j, i, bottom))
    return verts, np.array(faces, dtype=np.int64)

