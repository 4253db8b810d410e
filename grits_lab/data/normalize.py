"""Min-max normalization of poses, actions and point coordinates, shared by the policy and the predictor.

The 9-D action (xyz + 6-D rotation, grits_lab/geometry.py) is normalized as the authors' code
does: xyz min-max to [-1, 1], the 6-D rotation left as it is (its entries already lie in
[-1, 1], and rescaling them would distort the Gram-Schmidt projection back to a rotation).
`MinMaxNormalizer` is the general form (any subset of the last axis scaled); `ActionNormalizer`
fixes the subset to xyz. Both work on numpy arrays and on torch tensors (differentiably, so a
guidance gradient can flow through `unnormalize`), and save and load their statistics as plain
lists so that a checkpoint stays readable without pickling numpy objects.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from grits_lab.errors import InputError, StorageError

# A dimension whose data range is below this is treated as constant: it is shifted to 0 and
# not scaled, instead of dividing by (almost) zero and exploding any small test-time deviation.
MIN_RANGE = 1e-4


class MinMaxNormalizer:
    """Affine map of the dims in `scaled_dims` of the last axis from [min, max] to [-1, 1].

    Dims not in `scaled_dims` pass unchanged. Shapes: any `(..., D)`; statistics are `(D,)`.
    """

    def __init__(self, dim: int, scaled_dims: Sequence[int] | None = None) -> None:
        if dim <= 0:
            raise ValueError(f"`dim` must be positive. Got {dim}.")
        self.dim = int(dim)
        self.scaled_dims = tuple(range(dim)) if scaled_dims is None else tuple(int(d) for d in scaled_dims)
        if any(d < 0 or d >= dim for d in self.scaled_dims):
            raise ValueError(f"`scaled_dims` must lie in [0, {dim}). Got {self.scaled_dims}.")
        self.scale = np.ones(dim)  # x_norm = x * scale + offset
        self.offset = np.zeros(dim)
        self.data_min = np.zeros(dim)
        self.data_max = np.zeros(dim)
        self.fitted = False

    def fit(self, data: Any) -> "MinMaxNormalizer":
        """Fit on samples `(..., D)` (numpy or torch); NaN or inf in the data is refused."""
        array = _to_numpy(data)
        if array.ndim == 0 or array.shape[-1] != self.dim:
            raise InputError(f"normalizer expects data of shape (..., {self.dim}); got {array.shape}")
        array = array.reshape(-1, self.dim)
        if array.shape[0] == 0:
            raise InputError("cannot fit a normalizer on zero samples")
        if not np.all(np.isfinite(array)):
            raise InputError("cannot fit a normalizer on data containing NaN or inf")
        self.data_min = array.min(axis=0).astype(np.float64)
        self.data_max = array.max(axis=0).astype(np.float64)
        scale = np.ones(self.dim)
        offset = np.zeros(self.dim)
        for d in self.scaled_dims:
            span = self.data_max[d] - self.data_min[d]
            centre = 0.5 * (self.data_max[d] + self.data_min[d])
            scale[d] = 2.0 / span if span > MIN_RANGE else 1.0
            offset[d] = -centre * scale[d]
        self.scale, self.offset = scale, offset
        self.fitted = True
        return self

    def normalize(self, x: Any) -> Any:
        """World units -> normalized units; numpy in, numpy out; torch in, torch out (differentiable)."""
        scale, offset = self._coeffs_like(x)
        return x * scale + offset

    def unnormalize(self, x: Any) -> Any:
        """Normalized units -> world units; the exact inverse of `normalize`."""
        scale, offset = self._coeffs_like(x)
        return (x - offset) / scale

    def relative_affine(self, other: "MinMaxNormalizer") -> tuple[np.ndarray, np.ndarray]:
        """`(scale, offset)` with other.normalize(self.unnormalize(x)) == x * scale + offset.

        Maps a trajectory from this normalizer's space into `other`'s; both are `(D,)`, and the
        map is the identity when the two normalizers hold the same statistics.
        """
        self._check_fitted()
        other._check_fitted()
        scale = other.scale / self.scale
        offset = other.offset - self.offset * scale
        return scale, offset

    def state_dict(self) -> dict[str, Any]:
        self._check_fitted()
        return {
            "kind": type(self).__name__,
            "dim": self.dim,
            "scaled_dims": list(self.scaled_dims),
            "scale": self.scale.tolist(),
            "offset": self.offset.tolist(),
            "data_min": self.data_min.tolist(),
            "data_max": self.data_max.tolist(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> "MinMaxNormalizer":
        try:
            dim = int(state["dim"])
            if dim != self.dim:
                raise StorageError(f"normalizer state has dim {dim}, expected {self.dim}")
            self.scaled_dims = tuple(int(d) for d in state["scaled_dims"])
            self.scale = np.asarray(state["scale"], dtype=np.float64).reshape(dim)
            self.offset = np.asarray(state["offset"], dtype=np.float64).reshape(dim)
            self.data_min = np.asarray(state["data_min"], dtype=np.float64).reshape(dim)
            self.data_max = np.asarray(state["data_max"], dtype=np.float64).reshape(dim)
        except (KeyError, TypeError, ValueError) as exc:
            raise StorageError(f"invalid normalizer state: {exc}") from None
        self.fitted = True
        return self

    @classmethod
    def from_state_dict(cls, state: dict[str, Any]) -> "MinMaxNormalizer":
        if cls is MinMaxNormalizer:
            return MinMaxNormalizer(int(state["dim"]), state["scaled_dims"]).load_state_dict(state)
        return cls().load_state_dict(state)  # type: ignore[call-arg]

    def _coeffs_like(self, x: Any) -> tuple[Any, Any]:
        self._check_fitted()
        if _last_dim(x) != self.dim:
            raise InputError(f"normalizer expects shape (..., {self.dim}); got {tuple(x.shape)}")
        if _is_torch(x):
            import torch

            return (
                torch.as_tensor(self.scale, dtype=x.dtype, device=x.device),
                torch.as_tensor(self.offset, dtype=x.dtype, device=x.device),
            )
        dtype = x.dtype if np.issubdtype(np.asarray(x).dtype, np.floating) else np.float64
        return self.scale.astype(dtype), self.offset.astype(dtype)

    def _check_fitted(self) -> None:
        if not self.fitted:
            raise RuntimeError(f"{type(self).__name__} used before fit() or load_state_dict()")


class ActionNormalizer(MinMaxNormalizer):
    """9-D poses: xyz min-max to [-1, 1], 6-D rotation unchanged (contract 5)."""

    def __init__(self) -> None:
        super().__init__(9, scaled_dims=(0, 1, 2))


def _is_torch(x: Any) -> bool:
    return type(x).__module__.startswith("torch")


def _last_dim(x: Any) -> int:
    shape = tuple(x.shape) if hasattr(x, "shape") else np.shape(x)
    return int(shape[-1]) if shape else 0


def _to_numpy(x: Any) -> np.ndarray:
    if _is_torch(x):
        return x.detach().cpu().double().numpy()
    return np.asarray(x, dtype=np.float64)
