"""Perception on synthetic cameras with known geometry: back-projection, FPS, noise, composite clouds."""

import numpy as np
import pytest

from grits_lab.perception import CloudBuilder, CloudConfig, DepthNoiseConfig, corrupt_depth, depth_to_points, farthest_point_sample
from grits_lab.perception.clouds import object_points, pose_matrix
from grits_lab.seeding import make_rng

K = np.array([[100.0, 0, 32], [0, 100.0, 32], [0, 0, 1]])


def _look_down_camera(height):
    """Camera at (0, 0, height) looking straight down (-z world), OpenCV axes."""
    m = np.eye(4)
    m[:3, :3] = np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]], dtype=float)
    m[:3, 3] = [0, 0, height]
    return m


def _sphere_scene(center, radius, height=1.0, size=64):
    """Ray-cast a sphere over a floor at z=0: depth and segmentation (1 = sphere, 2 = floor)."""
    cam = _look_down_camera(height)
    v, u = np.mgrid[0:size, 0:size]
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u, float)], -1)
    dirs = rays @ cam[:3, :3].T  # world direction for unit camera z
    origin = cam[:3, 3]
    oc = origin - center
    b = np.einsum("hwi,i->hw", dirs, oc)
    a = np.einsum("hwi,hwi->hw", dirs, dirs)
    c = oc @ oc - radius**2
    disc = b * b - a * c
    t_sphere = np.where(disc > 0, (-b - np.sqrt(np.maximum(disc, 0))) / a, np.inf)
    t_floor = -origin[2] / dirs[..., 2]
    depth = np.minimum(t_sphere, t_floor)  # t is z-depth since the camera z component of rays is 1
    seg = np.where(t_sphere < t_floor, 1, 2)
    return {"depth": depth.astype(np.float32), "segmentation": seg, "intrinsics": K, "cam_to_world": cam}


def test_back_projection_recovers_geometry():
    center = np.array([0.02, -0.03, 0.05])
    cam = _sphere_scene(center, 0.08)
    pts = object_points([cam], {"sphere": 1, "floor": 2})
    dist = np.linalg.norm(pts["sphere"] - center, axis=1)
    assert len(pts["sphere"]) > 100
    np.testing.assert_allclose(dist, 0.08, atol=2e-3)
    np.testing.assert_allclose(pts["floor"][:, 2], 0.0, atol=1e-5)


def test_fps_exact_count_subset_and_deterministic():
    pts = make_rng(0).random((5000, 3))
    a = farthest_point_sample(pts, 300, seed=3)
    b = farthest_point_sample(pts, 300, seed=3)
    assert a.shape == (300, 3) and a.dtype == np.float32
    np.testing.assert_array_equal(a, b)
    assert len(np.unique(a, axis=0)) == 300
    # covers the cube: farthest-point sampling spreads out, random sampling clumps
    rand = pts[make_rng(1).choice(5000, 300, replace=False)]
    nn = lambda p: np.sort(np.linalg.norm(p[:, None] - p[None], axis=-1), axis=1)[:, 1].min()
    assert nn(a) > 2 * nn(rand)


def test_fps_pads_small_and_empty_sets():
    few = make_rng(0).random((10, 3))
    out = farthest_point_sample(few, 50, seed=0)
    assert out.shape == (50, 3)
    assert {tuple(p) for p in out.astype(np.float64).round(5)} <= {tuple(p) for p in few.round(5)}
    empty = farthest_point_sample(np.zeros((0, 3)), 20, fallback=[1, 2, 3])
    np.testing.assert_array_equal(empty, np.tile([1, 2, 3], (20, 1)))


def test_fps_gives_exactly_n_distinct_points_when_the_input_repeats_points():
    # a cloud merged from two cameras, or voxelized, holds exact duplicates
    distinct = make_rng(1).random((100, 3))
    repeated = distinct[make_rng(2).integers(0, 100, size=5000)]
    out = farthest_point_sample(repeated, 3000, seed=0)
    assert out.shape == (3000, 3)
    assert len(np.unique(out, axis=0)) == len(np.unique(repeated, axis=0))

    many = farthest_point_sample(np.unique(repeated, axis=0)[np.arange(5000) % 90], 64, seed=0)
    assert many.shape == (64, 3) and len(np.unique(many, axis=0)) == 64

    one = farthest_point_sample(np.tile([[0.1, 0.2, 0.3]], (500, 1)), 64, seed=0)
    np.testing.assert_allclose(one, np.tile([[0.1, 0.2, 0.3]], (64, 1)), rtol=1e-6)


def test_fps_drops_non_finite_points():
    pts = make_rng(3).random((5000, 3))
    pts[17] = np.nan
    pts[42, 1] = np.inf
    out = farthest_point_sample(pts, 64, seed=0)
    assert out.shape == (64, 3) and np.isfinite(out).all()
    nothing_finite = farthest_point_sample(np.full((5, 3), np.nan), 8, fallback=[1, 2, 3])
    np.testing.assert_array_equal(nothing_finite, np.tile([1, 2, 3], (8, 1)))


def test_numpy_farthest_point_sampling_picks_what_open3d_picks():
    """The numpy loop a plain install runs and open3d's C++ one choose the same indices, ties and
    repeated points included, on clouds like the cameras' (many points, few centimetres) and others."""
    pytest.importorskip("open3d", reason="the open3d extra is not installed: nothing to compare the numpy sampler with")
    from grits_lab.perception.clouds import _numpy_indices, _open3d_indices

    rng = np.random.default_rng(0)
    for case in range(60):
        m = int(rng.integers(2, 3000))
        points = rng.normal(size=(m, 3)) * rng.uniform(0.005, 0.5) + rng.uniform(-1, 1, 3)
        if case % 3 == 0:
            points = np.round(points, 2)  # equal distances (ties) and repeated points
        n, start = int(rng.integers(1, m + 1)), int(rng.integers(0, m))
        want = _open3d_indices(points, n, start)
        np.testing.assert_array_equal(_numpy_indices(points, n, start), want, err_msg=f"case {case}: m {m}, n {n}")


def test_farthest_point_sampling_is_the_same_with_and_without_open3d(monkeypatch):
    from grits_lab.perception import clouds

    pts = np.random.default_rng(4).uniform(-0.05, 0.05, (4000, 3))
    found = farthest_point_sample(pts, 256, seed=9)
    monkeypatch.setattr(clouds, "_open3d", lambda: None)
    np.testing.assert_array_equal(farthest_point_sample(pts, 256, seed=9), found)
    # open3d's rule on repeats: once every remaining point is at distance 0 the last pick repeats
    repeated = np.array([[0.0, 0, 0], [1, 0, 0], [1, 0, 0], [0, 0, 0]])
    np.testing.assert_array_equal(clouds.farthest_point_indices(repeated, 4, 0), [0, 1])


def test_depth_noise_grows_with_range_and_drops_pixels():
    cfg = DepthNoiseConfig(lateral_px=0.0, edge_dropout=0.0, random_dropout=0.05)
    near = np.full((200, 200), 0.5, np.float32)
    far = np.full((200, 200), 1.5, np.float32)
    noisy_near = corrupt_depth(near, 100.0, make_rng(0), cfg)
    noisy_far = corrupt_depth(far, 100.0, make_rng(0), cfg)
    dropped = (noisy_near == 0).mean()
    assert 0.03 < dropped < 0.07
    assert np.std(noisy_far[noisy_far > 0] - 1.5) > 3 * np.std(noisy_near[noisy_near > 0] - 0.5)
    # edges: a depth step loses pixels along it
    step = near.copy()
    step[:, 100:] = 1.0
    edge_cfg = DepthNoiseConfig(edge_dropout=1.0, random_dropout=0.0, lateral_px=0.0)
    noisy_step = corrupt_depth(step, 100.0, make_rng(0), edge_cfg)
    assert (noisy_step[:, 99:101] == 0).all() and (noisy_step[:, :98] > 0).all()


def _box_mesh(half):
    v = np.array([[x, y, z] for x in (-half[0], half[0]) for y in (-half[1], half[1]) for z in (-half[2], half[2])])
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return v, f


def test_composite_cloud_places_each_object_where_it_is():
    builder = CloudBuilder(CloudConfig(n_points=500, cad_surface_samples=4000), spoon_mesh=_box_mesh((0.03, 0.01, 0.005)), bowl_mesh=_box_mesh((0.08, 0.08, 0.03)))
    center = np.array([0.0, 0.0, 0.05])
    cam = _sphere_scene(center, 0.04)
    spoon_pose = pose_matrix([0.3, 0.1, 0.2], [0, 0, np.sin(0.4), np.cos(0.4)])
    bowl_pose = pose_matrix([-0.2, 0.0, 0.03], [0, 0, 0, 1])
    cloud = builder.composite([cam], food_ids=[1], spoon_pose=spoon_pose, bowl_pose=bowl_pose, seed=5)
    assert cloud.shape == (3, 500, 3) and cloud.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(cloud[0] - center, axis=1), 0.04, atol=2e-3)
    local_spoon = (cloud[1] - spoon_pose[:3, 3]) @ spoon_pose[:3, :3]
    assert np.all(np.abs(local_spoon) <= np.array([0.03, 0.01, 0.005]) + 1e-5)
    assert np.all(np.abs(cloud[2] - bowl_pose[:3, 3]) <= np.array([0.08, 0.08, 0.03]) + 1e-5)
    np.testing.assert_array_equal(cloud, builder.composite([cam], [1], spoon_pose, bowl_pose, seed=5))

    raw, visible = builder.raw([cam], {"food": [1], "spoon": [7], "bowl": [2]}, fallbacks={"food": center, "spoon": spoon_pose[:3, 3], "bowl": bowl_pose[:3, 3]}, seed=5)
    assert raw.shape == (3, 500, 3)
    assert visible["spoon"] == 0 and np.allclose(raw[1], spoon_pose[:3, 3])
    assert np.median(np.abs(np.linalg.norm(raw[0] - center, axis=1) - 0.04)) < 0.01
    assert not np.allclose(raw[0], cloud[0])
