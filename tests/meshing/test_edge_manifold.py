"""``weld.edge_manifold`` (edges as one int64 key each) against a row-by-row count of the same
edges, on closed, open, flipped, non-manifold, random, empty and huge-id face lists; and
``weld.unique_rows`` (one lexsort) against ``np.unique(axis=0)``."""

import numpy as np
import pytest
import trimesh
from ple.meshing.weld import edge_manifold


def by_rows(faces) -> dict:
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    counts: dict = {}
    for a, b in e.tolist():
        counts[(min(a, b), max(a, b))] = counts.get((min(a, b), max(a, b)), 0) + 1
    directed = {tuple(x) for x in e.tolist()}
    return {"bad_edges": sum(c != 2 for c in counts.values()),
            "oriented": len(directed) == len(e) and all(c == 2 for c in counts.values())}


sphere = np.asarray(trimesh.creation.icosphere(2).faces)
box = np.asarray(trimesh.creation.box().faces)
rng = np.random.default_rng(0)


@pytest.mark.parametrize("faces", [
    sphere, sphere[:-7], box[:, ::-1], np.concatenate([box, box[:3]]), np.concatenate([box, box[:1, ::-1]]),
    np.where(np.arange(len(box))[:, None] == 3, box[:, ::-1], box), rng.integers(0, 40, (500, 3)),
    np.zeros((0, 3), np.int64), box + 4_000_000_000, sphere + 3_037_000_000,
], ids=["sphere", "open", "flipped", "doubled", "one-reversed", "one-flipped", "random", "empty", "huge-ids",
        "ids-at-the-key-bound"])
def test_counts_as_row_by_row(faces):
    assert edge_manifold(faces) == by_rows(faces)


@pytest.mark.parametrize("rows", [
    rng.integers(-3, 3, (1000, 3)), rng.integers(0, 5, (50, 2)), np.zeros((0, 3), np.int64),
    rng.integers(-2**40, 2**40, (300, 3)), np.repeat(rng.integers(0, 9, (20, 3)), 5, axis=0)[rng.permutation(100)],
], ids=["small-range", "pairs", "empty", "wide-range", "repeated"])
def test_unique_rows_equals_numpy(rows):
    """``weld.unique_rows`` (one lexsort) gives np.unique(axis=0)'s first indices, inverse and
    counts, in its lexicographic order."""
    from ple.meshing.weld import unique_rows

    _, first, inv, cnt = np.unique(rows, axis=0, return_index=True, return_inverse=True, return_counts=True)
    f2, i2, c2 = unique_rows(rows)
    assert np.array_equal(first, f2) and np.array_equal(inv.reshape(-1), i2) and np.array_equal(cnt, c2)
