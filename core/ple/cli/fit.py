"""``ple fit MESH --out F.npz``: a T_d-symmetric Fourier field fitted to a closed mesh (004_ §3.2).

The mesh (STL, OBJ, PLY, GLB, … in cell units inside [-0.5, 0.5]³, or moved and scaled there
with ``--normalize``) is classified inside/outside on N³ grids, or with ``--distance`` its
signed distance is sampled there (the field then approximates the distance function); the
order N is the smallest of ``--orders`` whose zero level set is within ``--bound`` (Hausdorff,
cell units) of the mesh.
The coefficients file works as a filter: ``--implicit fourier:file=F.npz`` (Φ < 0 inside).
With ``--out F.json`` the field is written as inline ``ple-clg/1`` data instead,
``{"fourier": {...}}``: the ``replace`` of a CLG material (``ple.clg.field``).
"""

from __future__ import annotations

import math

import numpy as np

from ..clg.field import FieldSolid, field_to_dict
from ..errors import PleError, echo
from ..filters.fit import fit_mesh
from ..io.bodyfile import closed_mesh
from ..io.files import atomic_write_text, save_npz, strict_json
from ..model.budget import require
from .common import add_budget_args, max_memory


def register(sub) -> None:
    p = sub.add_parser("fit", help="fit a T_d-symmetric Fourier field to a closed mesh (coefficients .npz)")
    p.add_argument("mesh", help="a closed triangle mesh (.stl, .obj, .ply, .glb, .off)")
    p.add_argument("--out", required=True,
                   help="output coefficients .npz, or .json: a ple-clg/1 material's inline field")
    add_budget_args(p)
    p.add_argument("--bound", type=float, default=0.02, help="Hausdorff bound in cell units (default 0.02)")
    p.add_argument("--orders", default="8,16,32,64", help="candidate orders N, tried in order (default 8,16,32,64)")
    p.add_argument("--max-terms", type=int, default=None, help="keep about this many largest coefficients")
    p.add_argument("--no-symmetric", action="store_true", help="plain Fourier fit (no T_d projection)")
    p.add_argument("--distance", action="store_true",
                   help="fit the mesh's sampled signed distance (negative inside) instead of inside/outside")
    p.add_argument("--flip", action="store_true",
                   help="reverse the faces of an inverted (inside-out) mesh before fitting")
    p.add_argument("--normalize", action="store_true",
                   help="centre the mesh's box at the origin and scale its largest side to 0.9")
    p.set_defaults(func=run)


def load_mesh(path: str, flip: bool = False):
    """Vertices and faces of a closed mesh file that encloses a volume, outward: the body reader
    of every door (``ple.io.bodyfile.closed_mesh``); ``flip`` reverses an inverted mesh."""
    return closed_mesh(path, f"mesh {path}", flip)


MAX_ORDER = 256  # the fit samples an N³ grid
GRID_BYTES = 256  # per sample of an order's grid: inside flags, winding numbers, the FFT and copies (256³ passed 3 GiB)


def run(args) -> int:
    if not args.out.endswith((".npz", ".json")):
        raise PleError(f"--out {args.out}: expected a .npz or .json file")
    try:
        orders = [int(x) for x in args.orders.split(",") if x.strip()]
    except ValueError:
        raise PleError(f"--orders {echo(args.orders)}: expected integers like 8,16,32") from None
    if not orders or not all(2 <= n <= MAX_ORDER for n in orders):
        raise PleError(f"--orders {echo(args.orders)}: each order must be in 2..{MAX_ORDER}")
    require(max(orders) ** 3 * GRID_BYTES, f"--orders {args.orders}: a {max(orders)}³ grid", max_memory(args),
            "choose smaller --orders")
    if not (math.isfinite(args.bound) and args.bound > 0):
        raise PleError(f"--bound {args.bound}: must be a positive number")
    if args.max_terms is not None and args.max_terms < 1:
        raise PleError(f"--max-terms {args.max_terms}: must be at least 1")
    v, f = load_mesh(args.mesh, args.flip)
    transform = {"scale": 1.0, "offset": [0.0, 0.0, 0.0]}
    if args.normalize:
        lo, hi = v.min(axis=0), v.max(axis=0)
        scale = 0.9 / float((hi - lo).max())
        offset = -(lo + hi) / 2 * scale
        v = v * scale + offset
        transform = {"scale": scale, "offset": offset.tolist()}
    res = fit_mesh(v, f, bound=args.bound, orders=orders, symmetric=not args.no_symmetric,
                   max_terms=args.max_terms, distance=args.distance)
    arrays = res.field.arrays()
    if not (math.isfinite(res.hausdorff) and all(np.isfinite(np.asarray(a)).all() for a in arrays.values()
                                                 if np.asarray(a).dtype.kind in "fc")):
        raise PleError(f"mesh {args.mesh}: the fit is not finite (Hausdorff distance {res.hausdorff}); "
                       "the mesh must lie in the cell (or use --normalize)")
    if args.out.endswith(".json"):
        atomic_write_text(args.out, strict_json(field_to_dict(FieldSolid(res.field)), "the fitted field"))
    else:
        arrays.update(order=np.array(res.order), hausdorff=np.array(res.hausdorff), bound=np.array(res.bound),
                      scale=np.array(transform["scale"]), offset=np.array(transform["offset"]))
        save_npz(args.out, arrays)
    report = dict(res.report(), out=args.out, **transform)
    print(strict_json(report, "the fit report", indent=1))
    if not res.met:
        print(f"note: no order in {orders} meets the bound {args.bound}; wrote the closest (N={res.order})")
    return 0
