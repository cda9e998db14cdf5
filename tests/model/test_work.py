"""ple.model.budget as the add-on uses it: the work estimate of a region (exact balls and beams,
checked against evaluation) and the limits a front end checks it against."""

from __future__ import annotations

import pytest
from ple.errors import PleError
from ple.model.budget import Estimate, check, estimate
from ple.program.sources import load_lattice

REGIONS = ["0:3,0:3,0:3", "1:4,0:2,2:5", "0:1,0:1,0:1", "0:7,0:1,0:1"]


@pytest.mark.parametrize("preset", ["cubic", "octet", "fig6_3", "kagome", "cylindrical"])
@pytest.mark.parametrize("region", REGIONS)
def test_balls_and_beams_are_exact(preset, region):
    lat = load_lattice(preset)
    spans = [tuple(int(x) for x in part.split(":")) for part in region.split(",")]
    region = ",".join(f"{min(a, c - 1)}:{min(b, c)}" for (a, b), c in zip(spans, lat.counts))
    est = estimate(lat, region)
    ev = lat.evaluate_unfiltered(region)
    assert (est.balls, est.beams) == (len(ev.center), len(ev.beam_nodes))
    assert est.groups == lat.region(region).groups and est.triangles == 0


def test_huge_region_is_estimated_without_memory():
    lat = load_lattice("cubic")
    for axis in "uvw":
        d = getattr(lat, axis)
        getattr(lat, f"set_{axis}")(10**4, d.similarity)
    est = estimate(lat, "0:400,0:400,0:400")
    assert est.balls == 64_000_000 and est.beams == 3 * 400 * 400 * 399
    with pytest.raises(PleError, match=r"refused: 64 M node-groups: 64 M balls, 192 M beams, about [0-9.]+ GiB"):
        check(est, max_bytes=2 * 2**30, what="drawing")
    assert check(estimate(lat, "0:3,0:3,0:3"), max_bytes=2 * 2**30) is not None


def test_triangle_limit():
    est = Estimate(1, 1, 1, 5_000_000, 10)
    with pytest.raises(PleError, match="5 M triangles.*limit of 2 M triangles"):
        check(est, max_triangles=2_000_000)


def test_with_triangles_adds_their_memory():
    est = Estimate(1, 2, 3, 0, 1000)
    more = est.with_triangles(10)
    assert more.triangles == 10 and more.bytes > est.bytes and more.with_triangles(0) == est
