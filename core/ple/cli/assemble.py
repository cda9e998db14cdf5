"""``ple assemble URL --out F``: one file of a partitioned job — a mesh's STL parts concatenated
(streamed, never all parts in memory), or a filter job's parts as one ``.npz`` evaluation."""

from __future__ import annotations

from ..app.jobs import assemble_stl, load_filter_parts, location, read_manifest
from ..errors import PleError
from ..io.files import save_npz


def register(sub) -> None:
    p = sub.add_parser("assemble", help="one file of the parts of a job written with --parts")
    p.add_argument("parts", metavar="URL", help="the folder or fsspec URL given to --parts")
    p.add_argument("--out", required=True, help=".stl for a partitioned mesh, .npz for a partitioned filter")
    p.set_defaults(func=run)


def run(args) -> int:
    fs, root = location(args.parts, create=False)  # reading parts creates nothing
    kind = read_manifest(fs, root).get("kind")
    if kind == "mesh":
        if not args.out.endswith(".stl"):
            raise PleError(f"--out {args.out}: a partitioned mesh assembles into binary .stl")
        print(f"wrote {args.out}: {assemble_stl(args.parts, args.out):,} triangles")
    elif kind == "filter":
        if not args.out.endswith(".npz"):
            raise PleError(f"--out {args.out}: a partitioned filter assembles into .npz")
        ev = load_filter_parts(args.parts)
        save_npz(args.out, ev.arrays())
        print(f"wrote {args.out}: {len(ev.node_index):,} nodes, {len(ev.beam_index):,} beams")
    else:
        raise PleError(f"{args.parts}: no job manifest there (kind {kind!r})")
    return 0
