"""Point-cloud encoders of the predictor: DP3 (the paper's) and PointNet++ (its ablation), plain PyTorch.

Both take a normalized composite cloud `(B, K, N, 3)` with the K = 3 objects in the order of
`grits_lab.perception.composite.CLOUD_OBJECTS` (food, spoon, bowl) and return one embedding `(B, D)`.
Both are invariant to the order of the points within each object: DP3 by construction (a shared
per-point MLP and a max-pool); PointNet++ as far as farthest-point sampling allows (its first
centroid is the first point, so a permutation changes which centroids are drawn but not the
distribution they cover).
"""

from __future__ import annotations

import torch
from torch import nn

from grits_lab.spillage.predictor_config import DP3EncoderConfig, PointNet2EncoderConfig


def _check_cloud(cloud: torch.Tensor, n_objects: int) -> None:
    if cloud.ndim != 4 or cloud.shape[1] != n_objects or cloud.shape[3] != 3:
        raise ValueError(f"cloud must have shape (B, {n_objects}, N, 3); got {tuple(cloud.shape)}")


class DP3Encoder(nn.Module):
    """Per-point MLP (Linear + LayerNorm + ReLU) and max-pool, as the DP3 point encoder.

    Object identity: a learned per-object vector is added after the first linear layer, which is
    exactly a one-hot (food, spoon, bowl) input feature (W [xyz; onehot] = W_xyz xyz + w_obj) at
    a third of the cost. With `pool_per_object` each object is max-pooled on its own and the three
    pooled vectors are concatenated in a fixed order before the projection to `out_dim`.
    """

    def __init__(self, config: DP3EncoderConfig, n_objects: int = 3) -> None:
        super().__init__()
        self.config = config
        self.n_objects = n_objects
        dims = list(config.hidden_dims)
        self.first = nn.Linear(3, dims[0])
        self.identity = nn.Embedding(n_objects, dims[0]) if config.one_hot_identity else None
        if self.identity is not None:
            nn.init.normal_(self.identity.weight, std=0.5)
        self.first_norm = nn.LayerNorm(dims[0])
        layers: list[nn.Module] = []
        for d_in, d_out in zip(dims[:-1], dims[1:]):
            layers += [nn.Linear(d_in, d_out), nn.LayerNorm(d_out), nn.ReLU()]
        self.point_mlp = nn.Sequential(*layers)
        pooled = dims[-1] * (n_objects if config.pool_per_object else 1)
        self.projection = nn.Sequential(nn.Linear(pooled, config.out_dim), nn.LayerNorm(config.out_dim))
        self.out_dim = config.out_dim

    def forward(self, cloud: torch.Tensor) -> torch.Tensor:
        """(B, K, N, 3) normalized cloud -> (B, out_dim)."""
        _check_cloud(cloud, self.n_objects)
        h = self.first(cloud)  # (B, K, N, C0)
        if self.identity is not None:
            h = h + self.identity.weight[None, :, None, :]
        h = self.point_mlp(torch.relu(self.first_norm(h)))  # (B, K, N, C)
        if self.config.pool_per_object:
            pooled = h.amax(dim=2).flatten(1)  # (B, K * C)
        else:
            pooled = h.flatten(1, 2).amax(dim=1)  # (B, C)
        return self.projection(pooled)


def farthest_point_indices(xyz: torch.Tensor, n_samples: int) -> torch.Tensor:
    """Indices `(B, n_samples)` of a farthest-point sample of `xyz` `(B, N, 3)`, starting at point 0.

    Each next point is the one farthest from all points chosen so far; a point set with fewer
    than `n_samples` distinct points yields repeats once every distinct point is chosen.
    """
    b, n, _ = xyz.shape
    if n_samples > n:
        raise ValueError(f"cannot sample {n_samples} points from {n}")
    chosen = torch.zeros(b, n_samples, dtype=torch.long, device=xyz.device)
    min_dist = torch.full((b, n), float("inf"), device=xyz.device, dtype=xyz.dtype)
    batch = torch.arange(b, device=xyz.device)
    current = torch.zeros(b, dtype=torch.long, device=xyz.device)
    with torch.no_grad():
        for i in range(n_samples):
            chosen[:, i] = current
            centre = xyz[batch, current]  # (B, 3)
            min_dist = torch.minimum(min_dist, ((xyz - centre[:, None, :]) ** 2).sum(-1))
            current = min_dist.argmax(dim=1)
    return chosen


def ball_query(xyz: torch.Tensor, centroids: torch.Tensor, radius: float, n_neighbors: int) -> torch.Tensor:
    """Indices `(B, S, n_neighbors)` of points of `xyz` `(B, N, 3)` within `radius` of each centroid `(B, S, 3)`.

    As in PointNet++: the first `n_neighbors` points in index order; a ball with fewer points is
    padded with its first point. Every centroid drawn from `xyz` has at least itself in its ball.
    A centroid with an empty ball (possible only for centroids not from `xyz`) gets its nearest point.
    """
    n = xyz.shape[1]
    with torch.no_grad():
        dist2 = torch.cdist(centroids, xyz).pow(2)  # (B, S, N)
        index = torch.arange(n, device=xyz.device).expand_as(dist2)
        index = torch.where(dist2 <= radius * radius, index, torch.full_like(index, n))
        k = min(n_neighbors, n)
        first = torch.topk(index, k, dim=-1, largest=False, sorted=True).values  # (B, S, k)
        empty = first[..., :1] == n
        nearest = dist2.argmin(dim=-1, keepdim=True)
        head = torch.where(empty, nearest, first[..., :1])
        first = torch.where(first == n, head.expand_as(first), first)
        if k < n_neighbors:
            first = torch.cat([first, head.expand(-1, -1, n_neighbors - k)], dim=-1)
    return first


def _gather(points: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """points (B, N, C), index (B, ...) -> (B, ..., C)."""
    b = points.shape[0]
    flat = index.reshape(b, -1)
    out = torch.gather(points, 1, flat[..., None].expand(-1, -1, points.shape[-1]))
    return out.reshape(*index.shape, points.shape[-1])


class _SharedMLP(nn.Module):
    """Linear + norm + ReLU layers applied to the last axis of any `(..., C)` tensor."""

    def __init__(self, d_in: int, dims: tuple[int, ...], norm: str) -> None:
        super().__init__()
        self.linears = nn.ModuleList()
        self.norms = nn.ModuleList()
        for d_out in dims:
            self.linears.append(nn.Linear(d_in, d_out))
            self.norms.append(nn.BatchNorm1d(d_out) if norm == "batch" else nn.LayerNorm(d_out))
            d_in = d_out
        self.out_dim = d_in

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        shape = x.shape[:-1]
        x = x.reshape(-1, x.shape[-1])
        for linear, norm in zip(self.linears, self.norms):
            x = torch.relu(norm(linear(x)))
        return x.reshape(*shape, x.shape[-1])


class PointNet2Encoder(nn.Module):
    """PointNet++ single-scale grouping: set-abstraction levels, then a global MLP and max-pool.

    Objects are concatenated into one cloud of K*N points; identity is a one-hot feature per
    point, carried into the first level's neighbourhoods next to the relative coordinates.
    """

    def __init__(self, config: PointNet2EncoderConfig, n_objects: int = 3) -> None:
        super().__init__()
        self.config = config
        self.n_objects = n_objects
        d_feat = n_objects if config.one_hot_identity else 0
        self.levels = nn.ModuleList()
        for level in config.levels:
            mlp = _SharedMLP(3 + d_feat, level.mlp, config.norm)
            self.levels.append(mlp)
            d_feat = mlp.out_dim
        self.global_mlp = _SharedMLP(3 + d_feat, config.global_mlp, config.norm)
        self.projection = nn.Sequential(nn.Linear(self.global_mlp.out_dim, config.out_dim), nn.LayerNorm(config.out_dim))
        self.out_dim = config.out_dim

    def forward(self, cloud: torch.Tensor) -> torch.Tensor:
        """(B, K, N, 3) normalized cloud -> (B, out_dim)."""
        _check_cloud(cloud, self.n_objects)
        b, k, n, _ = cloud.shape
        xyz = cloud.reshape(b, k * n, 3)
        features = None
        if self.config.one_hot_identity:
            onehot = torch.eye(k, dtype=cloud.dtype, device=cloud.device)
            features = onehot[:, None, :].expand(k, n, k).reshape(1, k * n, k).expand(b, -1, -1)
        for spec, mlp in zip(self.config.levels, self.levels):
            n_centroids = min(spec.n_centroids, xyz.shape[1])
            centre_idx = farthest_point_indices(xyz, n_centroids)
            centres = _gather(xyz, centre_idx)  # (B, S, 3)
            group_idx = ball_query(xyz, centres, spec.radius, spec.n_neighbors)  # (B, S, k)
            grouped = _gather(xyz, group_idx) - centres[:, :, None, :]
            if features is not None:
                grouped = torch.cat([grouped, _gather(features, group_idx)], dim=-1)
            features = mlp(grouped).amax(dim=2)  # (B, S, C)
            xyz = centres
        assert features is not None
        h = self.global_mlp(torch.cat([xyz, features], dim=-1)).amax(dim=1)
        return self.projection(h)
