"""Write docs/performance.md and docs/img/performance.png from benchmarks/results/*.json."""

from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
DOCS = HERE.parent / "docs"


def _load(name: str):
    p = RESULTS / f"{name}.json"
    return json.loads(p.read_text()) if p.is_file() else None


def _ms(x) -> str:
    return "–" if x is None else (f"{x:.2f} ms" if x < 100 else f"{x / 1000:.2f} s")


def biq_section(d) -> list[str]:
    out = ["## Ball-interference queries (`ple bench biq`)", "",
           "100 random query balls (thesis protocol: centres in the box, radii 90–110 % of the mean radius).", "",
           "| lattice | nodes | path | ours, RangeFinder | thesis, RangeFinder (8 threads, i7-7700K) | ours vs naive "
           "| thesis naive |", "|---|---|---|---|---|---|---|"]
    for r in d["rows"]:
        out.append(f"| `{r['lattice']}` | {r['nodes']:,} | {r['path']} | {_ms(r['rangefinder_ms'])} | "
                   f"{_ms(r['thesis_rangefinder_ms'])} | {r['speedup_vs_naive']:,.0f}× | {r['thesis_naive_s']:.0f} s |")
    return out + [""]


def _n(x) -> str:
    return "–" if x is None else f"{x:,}"


def lil_section(d) -> list[str]:
    out = ["## Lattice-in-Lattice (`ple bench lil`)", "",
           "| case | ours | thesis (8 threads) | nodes kept | beams kept | KD-tree baseline (same run) |",
           "|---|---|---|---|---|---|"]
    for r in d.get("rows", []):
        if "seconds" not in r:
            continue
        thesis = r.get("thesis_seconds_8_threads")
        base = r.get("kdtree_baseline_seconds", r.get("naive_seconds"))
        label = r.get("fine", "") + (f" vs {r['coarse']}" if "coarse" in r else "")
        out.append(f"| {r['case']}{': ' + label if label else ''} | {r['seconds']:.3f} s | "
                   f"{'–' if thesis is None else f'{thesis} s'} | {_n(r.get('nodes_kept'))} | "
                   f"{_n(r.get('beams_kept'))} | {'–' if base is None else f'{base:.3f} s'} |")
    return out + ["", "Raw JSON (with the 10⁸-beam streaming run when `--big` is given): "
                  "`benchmarks/results/lil.json`.", ""]


def mesh_section(d) -> list[str]:
    st, big, reg = d["stl_write"], d["big_lattice"], d["region_vs_manifold3d"]
    out = ["## Tessellation (`ple bench mesh`)", "",
           f"- Binary STL writer: {st['ple_triangles_per_s'] / 1e6:.1f} M triangles/s "
           f"(trimesh's exporter, same mesh: {st['baseline_triangles_per_s'] / 1e6:.1f} M/s).",
           f"- {big['beams']:,}-beam {d['lattice']} lattice, style `{big['style']}`: {big['seconds']:.1f} s, "
           f"{big['triangles']:,} triangles, peak memory {big['peak_rss_gb']:.2f} GB.",
           f"- {reg['groups']:,}-group region vs the manifold3d union of ball and beam meshes "
           f"({reg['baseline_manifold3d_union']['seconds']:.2f} s):", "",
           "| style | seconds | triangles | volume | speed-up vs manifold3d |", "|---|---|---|---|---|"]
    for style, r in reg["ple"].items():
        out.append(f"| {style} | {r['seconds']:.2f} | {r['triangles']:,} | {r['volume']:.3f} | "
                   f"{reg['baseline_manifold3d_union']['seconds'] / r['seconds']:.1f}× |")
    return out + [""]


def measure_section(d) -> list[str]:
    out = ["## Area and volume (`ple bench measure`)", "",
           "| preset | groups | seconds | hub shapes measured | method | old per-hub path (extrapolated) |",
           "|---|---|---|---|---|---|"]
    for name, r in d["presets"].items():
        out.append(f"| `{name}` | {r['groups']:,} | {r['wall_s']:.2f} | {r['hub_geometries']:,} | "
                   f"{r['area_method']} | {r['baseline_extrapolated_s']:.1f} s |")
    return out + [""]


def generic_section(title: str, name: str, d) -> list[str]:
    return [f"## {title} (`ple bench {name}`)", "", "```json", json.dumps(d, indent=1)[:3000], "```", ""]


def plot(biq, lil) -> Path | None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    if biq is None:
        return None
    names = [r["lattice"].replace("thesis_", "") for r in biq["rows"]]
    ours = [r["rangefinder_ms"] for r in biq["rows"]]
    thesis = [r["thesis_rangefinder_ms"] for r in biq["rows"]]
    fig, ax = plt.subplots(figsize=(7, 3.4))
    x = range(len(names))
    ax.bar([i - 0.2 for i in x], thesis, 0.4, label="thesis (Java, 8 threads, i7-7700K)", color="#999")
    ax.bar([i + 0.2 for i in x], ours, 0.4, label="PLE (numpy, 2 cores)", color="#d08a3c")
    ax.set_yscale("log")
    ax.set_xticks(list(x), names)
    ax.set_ylabel("100 BIQs [ms], log scale")
    ax.set_title("Ball-interference queries, thesis protocol")
    ax.legend(frameon=False, fontsize=8)
    fig.tight_layout()
    out = DOCS / "img" / "performance.png"
    out.parent.mkdir(exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def write_report() -> Path:
    biq, lil, mesh, becots, ev = (_load(n) for n in ("biq", "lil", "mesh", "becots", "eval"))
    machine = _load("machine") or {}
    lines = ["# Performance", "",
             f"Measured by `make bench` (`benchmarks/run_all.py`) on {machine.get('cores', 2)} cores "
             f"({machine.get('machine', 'this machine')}), {machine.get('date', '')}; every benchmark times its "
             "baseline in the same run. The thesis prototype (Java, 8 threads, i7-7700K) is the bar (SPEC §8).", ""]
    if plot(biq, lil):
        lines += ["![BIQ timings beside the thesis](img/performance.png)", ""]
    if biq:
        lines += biq_section(biq)
    if lil:
        lines += lil_section(lil)
    if mesh:
        lines += mesh_section(mesh)
    measure = _load("measure")
    if measure:
        lines += measure_section(measure)
    for title, name, d in (("BeCOTS RangeFinder", "becots", becots), ("Lazy evaluation", "eval", ev)):
        if d:
            lines += generic_section(title, name, d)
    out = DOCS / "performance.md"
    out.write_text("\n".join(lines) + "\n")
    return out


if __name__ == "__main__":
    print(write_report())
