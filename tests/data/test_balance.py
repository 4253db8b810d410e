"""Balanced acceptance: buckets fill exactly, and the accepted set does not depend on arrival order."""

import numpy as np

from grits_lab.collection.balance import BalancedAcceptor
from grits_lab.seeding import derive_seed, make_rng


def _label(shape, k):
    # a deterministic "simulation": cubes spill rarely, spheres often
    p = {"sphere": 0.7, "cube": 0.2}[shape]
    return int(make_rng(derive_seed(0, shape, k)).random() < p)


def _run(order_seed, batch):
    acc = BalancedAcceptor({"sphere": (5, 5), "cube": (5, 5)}, max_candidates=500)
    rng = np.random.default_rng(order_seed)
    flying, accepted, tried = [], [], 0
    while not acc.done():
        while len(flying) < batch:
            nxt = acc.next_candidate({s: sum(1 for f in flying if f[0] == s) for s in ("sphere", "cube")})
            if nxt is None:
                break
            flying.append(nxt)
        # results arrive in random order
        shape, k = flying.pop(int(rng.integers(len(flying))))
        tried += 1
        accepted += [(d.shape, d.index) for d in acc.add(shape, k, _label(shape, k)) if d.accepted]
    return sorted(accepted), acc.counts(), tried


def test_buckets_fill_exactly_and_accepted_set_is_order_independent():
    a, counts, _ = _run(order_seed=1, batch=1)
    b, _, tried = _run(order_seed=2, batch=6)
    assert counts == {"sphere": {0: 5, 1: 5}, "cube": {0: 5, 1: 5}}
    assert a == b
    labels = [_label(s, k) for s, k in a]
    assert sum(labels) == 10 and len(a) == 20
    assert tried >= 20


def test_failed_candidates_are_skipped_and_cap_stops_search():
    acc = BalancedAcceptor({"cone": (1, 1)}, max_candidates=3)
    got = []
    while (nxt := acc.next_candidate({})) is not None:
        got += acc.add(*nxt, label=None if nxt[1] == 0 else 0)
    assert [d.accepted for d in got] == [False, True, False]
    assert acc.done() and not acc.full("cone")
