"""``ple assemble URL [--out F]``: one file of a partitioned job — a mesh's STL parts concatenated
(streamed, never all parts in memory), a filter job's parts as one ``.npz`` evaluation, a slice
job's parts as the slice folder of ``ple slice``; a count job's totals are printed."""

from __future__ import annotations

import posixpath

from ..app.jobs import assemble_slices, assemble_stl, count_totals, load_filter_parts, location, read_manifest
from ..errors import PleError, echo
from ..io.files import check_apart, save_npz


def register(sub) -> None:
    p = sub.add_parser("assemble", help="one file of the parts of a job written with --parts")
    p.add_argument("parts", metavar="URL", help="the folder or fsspec URL given to --parts")
    p.add_argument("--out", help=".stl for a partitioned mesh, .npz for a partitioned filter, a folder for "
                   "partitioned slices (a count job needs none: its totals are printed)")
    p.set_defaults(func=run, outputs=("out",))  # the parts folder is an input


def run(args) -> int:
    fs, root = location(args.parts, create=False)  # reading parts creates nothing
    manifest = read_manifest(fs, root)
    kind = manifest.get("kind")
    protocols = fs.protocol if isinstance(fs.protocol, tuple) else (fs.protocol,)
    if args.out and "file" in protocols:  # the output is none of the parts it reads
        check_apart({"--out": args.out}, {f"part {n}": posixpath.join(root, n) for n in manifest.get("order", [])})
    if kind == "count":
        totals = count_totals(args.parts)
        print(f"kept: {totals['nodes']:,} nodes, {totals['beams']:,} beams ({totals['parts']} parts)")
        return 0
    if not args.out:
        raise PleError(f"{args.parts}: a {kind} job assembles into a file: give --out")
    if kind == "slice":
        man = assemble_slices(args.parts, args.out)
        print(f"wrote {args.out}: {man['layers']} layers of {man['image_size'][0]}x{man['image_size'][1]} pixels")
    elif kind == "mesh":
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
        raise PleError(f"{args.parts}: no job manifest there (kind {echo(kind)})")
    return 0
