"""``ple becots map|inverse|connectors``: BeCOTS field evaluation, inversion and constant-radius
connectors (thesis §4.3.5, §4.5.3)."""

from __future__ import annotations

import math

import numpy as np

from ..app.pipeline import write_connectors
from ..errors import PleError, echo
from ..io.files import atomic_path, atomic_write_text, strict_json
from ..io.inputs import load_npy
from ..model.becots import BeCOTSField
from ..model.budget import MESH_TRIANGLE_BYTES, evaluation_bytes, region_beams, region_nodes, require
from .common import add_lattice_args, lattice_from_args, max_memory


def register(sub) -> None:
    p = sub.add_parser("becots", help="BeCOTS field map, inverse and constant-radius connectors")
    bsub = p.add_subparsers(dest="becots_cmd", metavar="map|inverse|connectors")
    bsub.required = True
    for name, helptext in (("map", "evaluate M(x, y) for (n, 2) parameters"),
                           ("inverse", "all valid (x, y) in [0,1]² for (n, 3) points, over every branch")):
        q = bsub.add_parser(name, help=helptext)
        q.add_argument("--corners", required=True, metavar='"ax,ay,az bx,by,bz cx,cy,cz dx,dy,dz"',
                       help="corners A=M(0,0), B=M(0,1), C=M(1,1), D=M(1,0)")
        q.add_argument("--branch", default="0,0", metavar="KU,KV", help="extra full turns of U and V (default 0,0)")
        if name == "map":
            q.add_argument("--uv", required=True, help="input .npy of shape (n, 2)")
            q.add_argument("--out", required=True, help="output .npy of points (n, 3)")
        else:
            q.add_argument("--points", required=True, help="input .npy of shape (n, 3)")
            q.add_argument("--out", required=True, help="output .json: for each point the list of [x, y]")
            q.add_argument("--tol", type=float, default=1e-9, help="relative distance to count as on the map")
        q.set_defaults(func=run)
    c = bsub.add_parser("connectors", help="constant-radius version: one mesh per connector class + beams")
    add_lattice_args(c)
    c.add_argument("--radius", type=float, required=True, help="common node radius")
    c.add_argument("--beam-radius", type=float, help="common beam (rod) radius (default radius / 2)")
    c.add_argument("--region", help="I0:I1,J0:J1,K0:K1 (default: the whole lattice)")
    c.add_argument("--out", required=True, help="output folder (new, empty, or written before by this command)")
    c.set_defaults(func=run)


def parse_corners(text: str) -> list[np.ndarray]:
    parts = text.split()
    if len(parts) != 4:
        raise PleError(f"--corners {echo(text)}: expected 4 points 'ax,ay,az bx,by,bz cx,cy,cz dx,dy,dz'")
    out = []
    for name, part in zip("ABCD", parts):
        try:
            xyz = [float(v) for v in part.split(",")]
        except ValueError:
            raise PleError(f"--corners: corner {name} {echo(part)} is not three numbers") from None
        if len(xyz) != 3 or not all(np.isfinite(xyz)):
            raise PleError(f"--corners: corner {name} {echo(part)} must be three finite numbers")
        out.append(np.array(xyz))
    return out


def _branch(text: str) -> tuple[int, int]:
    try:
        ku, kv = (int(v) for v in text.split(","))
    except ValueError:
        raise PleError(f"--branch {echo(text)}: expected two integers KU,KV") from None
    return ku, kv


def _load(path: str, cols: int, flag: str) -> np.ndarray:
    arr = load_npy(path, flag)
    if arr.ndim != 2 or arr.shape[1] != cols or not np.issubdtype(arr.dtype, np.number):
        raise PleError(f"{flag} {path}: expected a numeric array of shape (n, {cols}), got {arr.shape}")
    arr = arr.astype(float)
    if not np.all(np.isfinite(arr)):
        raise PleError(f"{flag} {path}: contains NaN or infinite values")
    return arr


def run(args) -> int:
    if args.becots_cmd == "connectors":
        for flag, value in (("--radius", args.radius), ("--beam-radius", args.beam_radius)):
            if value is not None and not (math.isfinite(value) and 0 < value < 1e150):
                raise PleError(f"{flag} {value}: expected a positive finite number")
        lat = lattice_from_args(args)
        region = lat.region(args.region)
        beams = region_beams(lat, region)
        require(2 * evaluation_bytes(lat, region) + beams * 48 * MESH_TRIANGLE_BYTES,
                f"the connectors of region {region} ({region_nodes(lat, region):,} nodes, {beams:,} beams)",
                max_memory(args), "choose a smaller --region")
        summary = write_connectors(lat, args.out, args.radius, args.beam_radius, region=args.region)
        print(f"wrote {len(summary['classes'])} connector classes and {summary['beams']} beams to {args.out}")
        return 0
    fld = BeCOTSField.from_corners(*parse_corners(args.corners), branch=_branch(args.branch))
    if args.becots_cmd == "map":
        if not args.out.endswith(".npy"):
            raise PleError(f"--out {args.out}: expected a .npy file")
        uv = _load(args.uv, 2, "--uv")
        with np.errstate(all="ignore"):
            pts = fld.points(uv[:, 0], uv[:, 1])
        bad = ~np.isfinite(pts).all(axis=1)
        if bad.any():
            row = int(np.argmax(bad))
            raise PleError(f"--uv {args.uv}: row {row} {uv[row].tolist()} maps to a non-finite point "
                           "(outside the field's domain or overflow); nothing written")
        with atomic_path(args.out) as tmp:
            with open(tmp, "wb") as fh:
                np.save(fh, pts)
        print(f"wrote {args.out}: {len(pts)} points ({fld.kind} field)")
        return 0
    if not (math.isfinite(args.tol) and args.tol >= 0):
        raise PleError(f"--tol {args.tol}: expected a finite number >= 0")
    pts = _load(args.points, 3, "--points")
    answers = fld.inverse(pts, tol=args.tol)
    atomic_write_text(args.out, strict_json([[list(xy) for xy in a] for a in answers], "the inverted points") + "\n")
    print(f"wrote {args.out}: {sum(len(a) for a in answers)} answers for {len(pts)} points")
    return 0
