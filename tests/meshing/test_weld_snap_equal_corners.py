"""``snapped_slices`` (the streamed STL's snap) drops exactly the faces ``snap_triangles`` drops:
corners equal as floats after the snap, signed zeros included (their bits differ)."""

from __future__ import annotations

import numpy as np
from ple.meshing.weld import snap_faces, snap_triangles


def test_snapped_faces_equal_the_triangle_snap_with_signed_zeros():
    rng = np.random.default_rng(0)
    g = 2.0**-10
    v = rng.uniform(-1, 1, (20000, 3))
    v[3000:3100] = v[3100:3200] + rng.uniform(-0.3, 0.3, (100, 3)) * g  # pairs that snap together
    v[3200:3300, 0] = rng.uniform(-0.4, 0.4, 100) * g  # x rounds to -0.0 or +0.0
    v[3300:3400] = v[3200:3300] * np.array([-1, 1, 1])  # the same points, x of the other sign
    f = rng.integers(0, 20000, (100000, 3))
    f[:5000] = rng.integers(3000, 3400, (5000, 3))
    ref = snap_triangles(v[f], g).astype(np.float32)  # every corner compared as floats
    got = snap_faces(v, f, g)
    t = snap_triangles(v[f], g)
    s = np.round(v[f] / g) * g
    edges = ((0, 1), (1, 2), (2, 0))
    bits_equal = [np.all(s[:, a].view(np.uint64) == s[:, b].view(np.uint64), axis=1) for a, b in edges]
    float_equal = [np.all(s[:, a] == s[:, b], axis=1) for a, b in edges]
    signed_only = np.any(float_equal, axis=0) & ~np.any(bits_equal, axis=0)
    assert len(t) < len(f) and signed_only.sum() > 5  # faces are dropped, some of them for signed zeros only
    assert got.tobytes() == ref.tobytes()
