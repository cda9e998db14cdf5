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


def lil_section(d) -> list[str]:
    out = ["## Lattice-in-Lattice (`ple bench lil`)", "", "| case | ours | thesis | nodes kept | beams kept |",
           "|---|---|---|---|---|"]
    for r in d.get("rows", []):
        name = r.get("case") or r.get("name") or r.get("fine")
        ours = r.get("seconds") or r.get("time_s") or r.get("lil_s")
        thesis = r.get("thesis_s")
        out.append(f"| {name} | {ours:.3f} s | {'–' if thesis is None else f'{thesis} s'} | "
                   f"{r.get('nodes_kept', '–'):,} | {r.get('beams_kept', '–'):,} |")
    return out + ["", "Raw JSON: `benchmarks/results/lil.json`.", ""]


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
    for title, name, d in (("Tessellation", "mesh", mesh), ("BeCOTS RangeFinder", "becots", becots),
                           ("Lazy evaluation", "eval", ev)):
        if d:
            lines += generic_section(title, name, d)
    out = DOCS / "performance.md"
    out.write_text("\n".join(lines) + "\n")
    return out


if __name__ == "__main__":
    print(write_report())
