"""Action normalization: round trips, ranges, torch gradients, saved state."""

import numpy as np
import pytest
import torch

from grits_lab.data.normalize import ActionNormalizer, MinMaxNormalizer
from grits_lab.errors import InputError


def _actions(seed=0, n=200):
    rng = np.random.default_rng(seed)
    xyz = rng.uniform([0.3, -0.2, 0.05], [0.6, 0.1, 0.4], size=(n, 3))
    rot = rng.uniform(-1, 1, size=(n, 6))
    return np.concatenate([xyz, rot], axis=1).astype(np.float32)


def test_xyz_maps_to_unit_range_and_rotation_is_untouched():
    actions = _actions()
    norm = ActionNormalizer().fit(actions)
    out = norm.normalize(actions)
    assert out.dtype == np.float32
    np.testing.assert_allclose(out[:, :3].min(axis=0), -1.0, atol=1e-6)
    np.testing.assert_allclose(out[:, :3].max(axis=0), 1.0, atol=1e-6)
    np.testing.assert_array_equal(out[:, 3:], actions[:, 3:])


def test_numpy_and_torch_round_trip_and_agree():
    actions = _actions(1).reshape(20, 10, 9)
    norm = ActionNormalizer().fit(actions)
    back = norm.unnormalize(norm.normalize(actions.astype(np.float64)))
    np.testing.assert_allclose(back, actions, atol=1e-9)
    t = torch.tensor(actions, dtype=torch.float64, requires_grad=True)
    nt = norm.normalize(t)
    np.testing.assert_allclose(nt.detach().numpy(), norm.normalize(actions.astype(np.float64)), atol=1e-12)
    # differentiable: d(unnormalize)/dx is 1/scale per dim
    y = norm.unnormalize(t).sum()
    y.backward()
    np.testing.assert_allclose(t.grad[0, 0].numpy(), 1.0 / norm.scale, rtol=1e-12)


def test_state_dict_round_trip_gives_identical_maps():
    actions = _actions(2)
    norm = ActionNormalizer().fit(actions)
    restored = ActionNormalizer.from_state_dict(norm.state_dict())
    x = _actions(3)
    np.testing.assert_array_equal(restored.normalize(x), norm.normalize(x))


def test_relative_affine_maps_between_spaces_and_is_identity_for_same_stats():
    a = ActionNormalizer().fit(_actions(4))
    b = ActionNormalizer().fit(_actions(5, n=50))
    x = a.normalize(_actions(6).astype(np.float64))
    scale, offset = a.relative_affine(b)
    np.testing.assert_allclose(x * scale + offset, b.normalize(a.unnormalize(x)), atol=1e-12)
    scale, offset = a.relative_affine(a)
    np.testing.assert_allclose(scale, 1.0)
    np.testing.assert_allclose(offset, 0.0, atol=1e-15)


def test_constant_dimension_is_shifted_not_blown_up():
    data = np.zeros((10, 3))
    data[:, 0] = np.linspace(0, 1, 10)
    data[:, 1] = 0.25
    norm = MinMaxNormalizer(3).fit(data)
    out = norm.normalize(data + 0.01)
    assert np.allclose(out[:, 1], 0.01)


def test_bad_input_is_refused_with_a_clear_error():
    with pytest.raises(InputError, match="shape"):
        ActionNormalizer().fit(np.zeros((4, 7)))
    with pytest.raises(InputError, match="NaN"):
        ActionNormalizer().fit(np.full((4, 9), np.nan))
    with pytest.raises(RuntimeError, match="before fit"):
        ActionNormalizer().normalize(np.zeros((1, 9)))
