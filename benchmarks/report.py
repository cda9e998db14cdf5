"""Write docs/performance.md and docs/img/performance.png from benchmarks/results/*.json."""

from __future__ import annotations

import json
import re
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
           "100 random query balls (thesis protocol, §7.4: centres in the box, radii 90–110 % of the mean radius). "
           "Naive: the lattice evaluated once (not timed here), then every query tested exactly against every "
           "node and beam, vectorized in numpy over all elements; timed on "
           f"{d['rows'][0].get('naive_scaled_from_queries', '–') if d.get('rows') else '–'} queries and scaled to 100. "
           "The thesis' figures are its Table 7.2 (Java, one thread, i7-7700K), unscaled.", "",
           "| lattice | nodes | path | ours, RangeFinder | thesis, best path (one thread) | ours, naive "
           "| thesis, naive (one thread) | ours vs naive | thesis vs naive |", "|---|---|---|---|---|---|---|---|---|"]
    for r in d["rows"]:
        theirs = r["thesis_naive_s"] * 1e3 / r["thesis_rangefinder_ms"] if r.get("thesis_naive_s") else None
        out.append(f"| `{r['lattice']}` | {r['nodes']:,} | {r['path']} | {_ms(r['rangefinder_ms'])} | "
                   f"{_ms(r['thesis_rangefinder_ms'])} | {r['naive_s']:.1f} s | {r['thesis_naive_s']:.0f} s | "
                   f"{r['speedup_vs_naive']:,.0f}× | {'–' if theirs is None else f'{theirs:,.0f}×'} |")
    kd = d.get("kdtree")
    if kd:
        out += ["", f"### Against a prebuilt KD-tree: `{kd['lattice']}` "
                f"{'×'.join(map(str, kd['counts']))}, {kd['queries']:,} BIQs", "",
                f"{kd['uniform_queries']} balls uniform in the bounds (radii 90–110 % of the mean radius) and "
                f"{kd['near_node_queries']} at random nodes plus noise with 3× the node's radius: {kd['node_hits']:,} "
                f"node hits, {kd['beam_hits']:,} beam hits. The user's alternative evaluates the lattice, builds a "
                "`scipy.spatial.cKDTree` over the ball centres (nodes only) or over the centres and the beam "
                "midpoints (nodes and beams), asks it once for all queries and tests the candidates exactly, "
                "vectorized in numpy. PLE evaluates nothing: its first call builds a per-lattice plan from the base "
                f"slab (path `{kd['path']}`, `ple.queries.pullback`, {kd.get('form', 'numpy')} form). Query "
                f"times are the best of {kd['repeat']} warm runs of all queries, in the same process"
                + (f", load average {kd['load_average_1min']:.1f} on {d['cpus']} cores" if "load_average_1min" in kd
                   else "") + ".", "",
                "| mode | PLE | PLE first call (plan) | tree, queries | tree build | evaluation | PLE vs tree, per "
                "query | same hits |", "|---|---|---|---|---|---|---|---|"]
        for mode, label in (("nodes_only", "nodes only"), ("nodes_and_beams", "nodes and beams")):
            m = kd[mode]
            out.append(f"| {label} | {_ms(m['ple_ms'])} ({m['ple_us_per_query']:.1f} µs a query) | "
                       f"{_ms(m['ple_first_call_ms'])} | "
                       f"{_ms(m['tree_ms'])} ({m['tree_us_per_query']:.1f} µs a query) | "
                       f"{m['tree_build_s']:.2f} s | {m['evaluation_s']:.2f} s | {m['speedup_vs_tree']:.2f}× | "
                       f"{'yes' if m['same_hits'] else 'NO'} |")
    return out + [""]


def _n(x) -> str:
    return "–" if x is None else f"{x:,}"


def lil_section(d) -> list[str]:
    out = ["## Lattice-in-Lattice (`ple bench lil`)", "",
           "Ours: one BIQ per fine node (one thread). The seeds' figures (8 threads) are their best path, "
           "each beside the run of the same size: thesis Table 7.1 (i7-7700K) for the 75³ and 32×128×128 fine "
           "lattices, the RangeFinder paper's Table 1 (i7-6820HQ, Fig. 12) for the 64³ semi-regular case. "
           "The naive baseline tests every fine ball against every coarse element, vectorized in numpy over all "
           "fine balls, one coarse element at a time.",
           "", "| case | ours | seed (8 threads) | nodes kept | beams kept | KD-tree or naive baseline (same run) |",
           "|---|---|---|---|---|---|"]
    for r in d.get("rows", []):
        if "seconds" not in r:
            continue
        thesis = r.get("seed_seconds_8_threads")
        src = f" ({r['seed_source']})" if r.get("seed_source") else ""
        base = r.get("kdtree_baseline_seconds", r.get("naive_seconds"))
        label = r.get("fine", "") + (f" vs {r['coarse']}" if "coarse" in r else "")
        out.append(f"| {r['case']}{': ' + label if label else ''} | {r['seconds']:.3f} s | "
                   f"{'–' if thesis is None else f'{thesis} s{src}'} | {_n(r.get('nodes_kept'))} | "
                   f"{_n(r.get('beams_kept'))} | {'–' if base is None else f'{base:.3f} s'} |")
    thesis = [r for r in d.get("rows", []) if "thesis_us_per_biq_per_thread" in r]
    if thesis:
        out += ["", "Thesis Table 7.1 by its own method: two BIQs per valid fine beam against the coarse lattice, "
                f"{thesis[0]['workers']} processes; paths marked \"all\" ran every BIQ, the others a sample "
                "extrapolated to all. Ours per BIQ in CPU µs; theirs = the total × 8 threads ÷ BIQs (thesis "
                "Table 7.1, i7-7700K; RangeFinder paper Table 1, i7-6820HQ). The pulled-back query (`pullback`) "
                "answers the general case, so it stands beside the seeds' O(ūv̄) figures.", "",
                "| case | BIQs | path | ours, CPU µs a BIQ | thesis / paper, µs a BIQ per thread | ours, CPU s per "
                "process | thesis / paper, 8 threads |", "|---|---|---|---|---|---|---|"]
        g = lambda d, k, f, unit="": "–" if k not in d else format(d[k], f) + unit  # noqa: E731
        for r in thesis:
            t, p = r["thesis_us_per_biq_per_thread"], r.get("rangefinder_us_per_biq_per_thread", {})
            ts, ps = r["thesis_seconds_8_threads"], r.get("rangefinder_table_1_seconds_8_threads", {})
            for path, v in r["ours"].items():
                run = "all" if v["all_biqs_run"] else "extrap."
                ref = "uv" if path == "pullback" else path  # the seeds' general-case path
                label = "pullback (vs O(ūv̄))" if path == "pullback" else path
                out.append(f"| {r['case']} | {r['biqs']:,} | {label} | {v['cpu_us_per_biq']:.3g} | "
                           f"{g(t, ref, '.3g')} / {g(p, ref, '.3g')} | "
                           f"{v['extrapolated_cpu_seconds_on_workers']:.3g} s ({run}) | "
                           f"{g(ts, ref, '.4g', ' s')} / {g(ps, ref, '.4g', ' s')} |")
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
    ax.bar([i - 0.2 for i in x], thesis, 0.4, label="thesis Table 7.2 (Java, one thread, i7-7700K)", color="#999")
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


def curved_section(d) -> list[str]:
    """Issue 14's table (``ple bench curved``, also the ``lattices`` rows of ``ple bench mesh``)."""
    la = d.get("load_average_at_start", [None])[0]
    out = ["## Curved lattices (`ple bench curved`)", "",
           "Regular, curved and warped lattices streamed to binary STL (float32 snap included), each run in a "
           "child process of its own (peak memory is that run's VmHWM): the per-hub path "
           "(`Tessellator(batched=False)`, one CHoCC per hub shape) as the baseline, the batched hub templates on "
           "1 and 2 workers, the STL writer alone on the same triangles (this machine's ceiling; in brackets, "
           "writing the file's bytes alone from memory the way the writer writes, past the page cache here: "
           "the disk's floor), and the cleanliness check `ple mesh` runs first; last, `ple mesh` end to end on "
           "2 workers (check, then the "
           "checked stream reusing its hub templates, or the exact unions). The curved lattice: "
           "translation U, rotation V about z, swirl W, "
           "one ball, 4 beam-patterns (every (i, j) column its own hub shape); regular: the same beams on "
           "translations; warped: the `warped` preset. Each batched cell is the fastest of "
           f"{d.get('repeat', 1)} runs (every run's seconds are in the JSON: page faults and the file's page cache "
           "vary by seconds on this VM); the per-hub baseline is one run. In brackets under 2 workers: CPU "
           "seconds, user + system (template processes included). *No file*: the same stream, its records "
           "counted instead of written (the computation without the file system)."
           + (f" Load average at the start: {la:.2f}." if la is not None else ""), "",
           "![Triangles per second, per-hub vs batched vs the writer alone](img/curved_throughput.png)", "",
           "| lattice | style | triangles | per-hub | batched, 1 worker | batched, 2 workers | no file, 2 workers "
           "| speed-up vs per-hub | writer alone | peak memory | check (unclean hubs) | `ple mesh`, 2 workers |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]

    def cell(r):
        return "–" if r is None else f"{r['seconds']:.2f} s, {r['triangles_per_s'] / 1e6:.2f} M/s"

    def cpu(r):
        return "" if r is None or "cpu_user_s" not in r else f" (CPU {r['cpu_user_s']:.1f} + {r['cpu_sys_s']:.1f} s)"

    for row in d["rows"]:
        runs = {(r["path"], r["workers"]): r for r in row["runs"]}
        style = row["style"] + (f" L{row['levels']}" if row["style"] == "refined" else "")
        whole = row.get("ple_mesh")
        peak = max(r["peak_rss_gb"] for r in row["runs"])
        whole_cell = "–" if whole is None else f"{cell(whole)}, {whole['peak_rss_gb']:.2f} GB"
        alone = row["stl_writer_only"].get("bytes_alone_s")
        disk = "" if alone is None else f" ({alone:.2f} s for {row['stl_writer_only']['bytes'] / 1e9:.2f} GB)"
        chk = row["cleanliness_check"]
        sp = row.get("speedup_vs_per_hub")
        out.append(f"| {row['lattice']} {row['n']}³ | {style} | {row['runs'][-1]['triangles']:,} | "
                   f"{cell(runs.get(('per-hub', 1)))} | {cell(runs.get(('batched', 1)))} | "
                   f"{cell(runs.get(('batched', 2)))}{cpu(runs.get(('batched', 2)))} | "
                   f"{cell(runs.get(('batched, no file', 2)))}{cpu(runs.get(('batched, no file', 2)))} | "
                   f"{'–' if sp is None else f'{sp:.1f}×'} | "
                   f"{cell(row['stl_writer_only'])}{disk} | {peak:.2f} GB | "
                   f"{chk['check_s']:.1f} s ({chk['unclean_hubs']:,}) | {whole_cell} |")
    return out + ["", "Raw JSON: `benchmarks/results/curved.json`.", ""]


def plot_curved(d) -> Path | None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    if not d or not d.get("rows"):
        return None
    labels, series = [], {"per-hub": [], "batched, 1 worker": [], "batched, 2 workers": [], "writer alone": []}
    def cpu(r):
        return "" if r is None or "cpu_user_s" not in r else f" (CPU {r['cpu_user_s']:.1f} + {r['cpu_sys_s']:.1f} s)"

    for row in d["rows"]:
        runs = {(r["path"], r["workers"]): r for r in row["runs"]}
        labels.append(f"{row['lattice']} {row['n']}³\n{row['style']}")
        for name, key in (("per-hub", ("per-hub", 1)), ("batched, 1 worker", ("batched", 1)),
                          ("batched, 2 workers", ("batched", 2))):
            series[name].append(runs[key]["triangles_per_s"] / 1e6 if key in runs else 0.0)
        series["writer alone"].append(row["stl_writer_only"]["triangles_per_s"] / 1e6)
    fig, ax = plt.subplots(figsize=(8, 3.6))
    width = 0.2
    colors = ["#999", "#e0b070", "#d08a3c", "#4a7ab0"]
    for k, (name, vals) in enumerate(series.items()):
        ax.bar([i + (k - 1.5) * width for i in range(len(labels))], vals, width, label=name, color=colors[k])
    ax.axhline(2.0, color="#c33", lw=1, ls="--", label="issue 14's target, 2 M/s")
    ax.set_xticks(range(len(labels)), labels, fontsize=8)
    ax.set_ylabel("million triangles / s to binary STL")
    ax.set_title("Regular, curved and warped lattices to binary STL (2 cores)")
    ax.legend(frameon=False, fontsize=7, ncol=3)
    fig.tight_layout()
    out = DOCS / "img" / "curved_throughput.png"
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def _cell(r: dict) -> str:
    block = ""
    if "block_cpu_seconds_scaled" in r:
        block = (f"; its {r['block']}³ corner: CPU {r['block_cpu_seconds']:.1f} s × {r['elements_ratio']:.1f} "
                 f"(elements) = ≥ {r['block_cpu_seconds_scaled']:.0f} s")
    if "timeout" in r:
        return f"stopped at {r['timeout']:.0f} s{block}"
    if "memory_limit_gb" in r:
        return (f"stopped at its {r['memory_limit_gb']:.0f} GB limit after CPU {r['cpu_seconds_until_stopped']:.0f} s"
                f"{block}")
    if "error" in r:
        return f"error: {r['error']}"
    return f"{r['seconds']:.1f} s (CPU {r['cpu_seconds']:.1f} s), {r['peak_rss_gb']:.2f} GB, {r['triangles']:,} tri"


def unclean_section(d) -> list[str]:
    out = ["## Unclean lattices (`ple bench unclean`)", "",
           "Each case streamed to binary STL by `ple mesh`'s own path in a fresh process, beside one manifold3d "
           "batch union of the same balls (32 segments) and cone-beams in a fresh process of its own, stopped after "
           f"{d['union_timeout_s']:.0f} s or at {d.get('union_memory_gb', 12):.0f} GB of address space; then the CPU "
           "speed-up is a lower bound (≥): the larger of the CPU spent until stopped and the union of the lattice's "
           "corner block of a third of its groups along each index, scaled by the ratio of elements (a union's work "
           "grows at least linearly with its elements). Estimate: the process's own "
           "baseline, the region's evaluation, two boxes and the largest local union, computed before any work."
           + (f" {d['note']}." if d.get("note") else ""), "",
           "![unclean lattices: ours vs one manifold3d union](img/unclean.png)", "",
           "| case | style | ours | triangles / CPU s | estimate (peak / estimate) | manifold3d union | CPU speed-up | "
           "what was unclean |", "|---|---|---|---|---|---|---|---|"]
    for r in d["rows"]:
        o, b = r["ours"], r["manifold3d_union"]
        name = r["case"] + (f" {r['n']}³" if r["n"] else "")
        style = r["style"] + (f" {r['levels']}" if r["style"] == "refined" else "")
        if "seconds" not in o:
            out.append(f"| {name} | {style} | {_cell(o)} | – | – | {_cell(b)} | – | – |")
            continue
        speed = r.get("cpu_speedup")
        sp = "–" if speed is None else f"{'≥ ' if r.get('speedup_is_lower_bound') else ''}{speed:.1f}×"
        what = (o.get("unclean") or "not checked").replace("unclean lattice: ", "")
        what = what.replace(" united with manifold3d", "")
        out.append(f"| {name} | {style} | {_cell(o)} | {o['triangles'] / max(o['cpu_seconds'], 1e-9) / 1e6:.2f} M/s | "
                   f"{o['estimate_gb']:.2f} GB ({o['peak_over_estimate']:.2f}) | {_cell(b)} | {sp} | {what} |")
    return out + ["", "Raw JSON: `benchmarks/results/unclean.json`.", ""]


def plot_unclean(d) -> Path | None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = [r for r in (d or {}).get("rows", []) if "cpu_seconds" in r["ours"]]
    if not rows:
        return None
    labels = [f"{r['case']} {r['n'] or ''}\n{r['style']}" for r in rows]
    ours = [r["ours"]["cpu_seconds"] for r in rows]
    base = [r["manifold3d_union"].get("cpu_seconds", r["cpu_speedup"] * r["ours"]["cpu_seconds"]) for r in rows]
    fig, ax = plt.subplots(figsize=(8, 3.6))
    x = range(len(rows))
    ax.bar([i - 0.2 for i in x], ours, 0.4, label="ple mesh (CPU s)", color="#4a7ab0")
    ax.bar([i + 0.2 for i in x], base, 0.4, label="one manifold3d union (CPU s; hatched: lower bound)", color="#999",
           hatch=None)
    for i, r in enumerate(rows):
        if "cpu_seconds" not in r["manifold3d_union"]:
            ax.bar(i + 0.2, base[i], 0.4, color="none", edgecolor="#333", hatch="//")
    ax.set_yscale("log")
    ax.set_xticks(list(x), labels, fontsize=7)
    ax.set_ylabel("CPU seconds (log)")
    ax.set_title("Unclean lattices: local unions vs one global union (2 cores)")
    ax.legend(frameon=False, fontsize=7)
    fig.tight_layout()
    out = DOCS / "img" / "unclean.png"
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def plot_addon(d) -> Path | None:
    """Drag time against the drawn balls and beams, today's redraw and ours (``ple bench addon``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = sorted((r for r in (d or {}).get("rows", []) if r["lattice_groups"] <= 10**6),
                  key=lambda r: r["balls"] + r["beams"])
    if not rows:
        return None
    x = [r["balls"] + r["beams"] for r in rows]
    fig, ax = plt.subplots(figsize=(7.5, 3.8))
    for side, colour, label in (("today", "#888", "before (swept beams, every move redrawn)"),
                                ("ours", "#2a62b0", "after (instances, G a transform, hull while moving)")):
        ax.plot(x, [r[side]["drag_u_ms"] for r in rows], "o-", color=colour, label=f"drag U, {label}")
        ax.plot(x, [r[side]["drag_g_ms"] for r in rows], "s--", color=colour, label=f"drag G, {label}")
    settle = [(xi, r["ours"]["settle_ms"]) for xi, r in zip(x, rows) if r["ours"].get("settle_ms", 0) > 1]
    if settle:
        ax.plot(*zip(*settle), "^:", color="#2a62b0", alpha=0.6, label="after: full drawing on release")
    for ms, name in ((100, "100 ms"), (20, "20 ms")):
        ax.axhline(ms, color="#c33", lw=0.8, ls=":")
        ax.text(x[0], ms * 1.08, name, color="#c33", fontsize=7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("balls + beams in the drawn region")
    ax.set_ylabel("ms per move (median)")
    ax.set_title("Blender: one move of a frame, handler and geometry nodes (2 cores)")
    ax.legend(frameon=False, fontsize=7, loc="upper left")
    fig.tight_layout()
    out = DOCS / "img" / "addon_drag.png"
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def addon_section(d) -> list[str]:
    out = ["## Live editing in Blender (`ple bench addon`)", "",
           f"A cubic lattice, each case in a fresh bpy process; *today* is the add-on and core at "
           f"`{d['baseline_rev']}` in the same run. Medians of the moves; peak: the whole process.", "",
           "![Drag time against drawn elements, before and after](img/addon_drag.png)", "",
           "| lattice | drawn groups | balls + beams | drag G | drag U | count change | first draw | full on release "
           "| peak | drawn while moving |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in d["rows"]:
        o, t = r["ours"], r["today"]
        side = round(r["lattice_groups"] ** (1 / 3))
        out.append(f"| cubic {side}³ | {r['drawn_groups']:,} | {r['balls'] + r['beams']:,} | "
                   f"{_ms(o['drag_g_ms'])} ({_ms(t['drag_g_ms'])}) | {_ms(o['drag_u_ms'])} ({_ms(t['drag_u_ms'])}) | "
                   f"{_ms(o['counts_ms'])} ({_ms(t['counts_ms'])}) | {o['first_draw_s']:.2f} s "
                   f"({t['first_draw_s']:.2f} s) | {_ms(o['settle_ms'])} | {o['peak_gb']:.2f} GB "
                   f"({t['peak_gb']:.2f} GB) | {o['drawn_while_dragging']:,} |")
    return out + ["", "Ours first, today's in brackets. Raw JSON: `benchmarks/results/addon.json`.", ""]


def presets_section(d) -> list[str]:
    """Every preset with its defaults in every closed style (``ple bench presets``)."""
    rows = d.get("rows", [])
    styles = list(dict.fromkeys(r["style"] for r in rows))
    verdict = "All meshed." if d.get("all_meshed") else "Failures below."
    out = ["## Every preset, every style (`ple bench presets`)", "",
           "`ple mesh NAME --style STYLE` with the preset's defaults, each in a fresh process (CPU seconds of the "
           f"command; `ple info` beside it as the baseline). {verdict}"
           + (f" {d['note']}." if d.get("note") else ""), "",
           "| preset | `ple info` | " + " | ".join(styles) + " |", "|---|---|" + "---|" * len(styles)]
    by = {}
    for r in rows:
        by.setdefault(r["preset"], {})[r["style"]] = r
    for name, cells in by.items():
        info = next(iter(cells.values())).get("info_seconds")
        line = [name, "–" if info is None else f"{info:.1f} s"]
        for st in styles:
            r = cells.get(st)
            if r is None:
                line.append("–")
            elif "timeout" in r:
                line.append(f"stopped at {r['timeout']:.0f} s")
            elif r.get("exit") != 0:
                line.append(f"exit {r['exit']}: {r.get('last', '')[:80]}")
            else:
                tris = r.get("triangles")
                fewer = re.search(r"meshing at (\d+) levels", r.get("note") or "")
                line.append(f"{r['cpu_seconds']:.1f} s" + (f", {tris:,} tri" if tris else "")
                            + (f" at {fewer.group(1)} levels" if fewer else "")
                            + (" (unions)" if r.get("unclean") and "local union" in r["unclean"] else ""))
        out.append("| " + " | ".join(line) + " |")
    return out + ["", "Raw JSON: `benchmarks/results/presets.json`.", ""]


def startup_section(d) -> list[str]:
    rows = d.get("startup") or d.get("commands")
    if not rows:
        return []
    out = ["## Start-up (`ple bench startup`)", "", "Whole processes, 10 runs each, interleaved; target: `ple presets` "
           "median ≤ 0.3 s.", "", "| command | median | min | max |", "|---|---|---|---|"]
    for name, r in rows.items():
        out.append(f"| `{name}` | {r['median_s']:.3f} s | {r['min_s']:.3f} s | {r['max_s']:.3f} s |")
    return out + [""]


def clg_budget_section(d) -> list[str]:
    """The CLG mesh budget's estimate against the measured peak (``ple bench clg_budget``)."""
    out = ["## CLG mesh budget (`ple bench clg_budget`)", "",
           f"The estimate `ple clg mesh` is refused by (triangles × 650 B, nested materials as meshed) against "
           f"the peak proportional set size of the command and its child, sampled every 10 ms; "
           f"`--segments {d['segments']}`, load average {d['load'][0]:.1f}. The promise: the peak within "
           f"{d['limit']}× the estimate (worst here {d['worst']:.2f}×).", "",
           "| case | groups | bound (triangles) | estimate (triangles) | estimate | peak | peak / estimate |",
           "|---|---|---|---|---|---|---|"]
    for r in d["rows"]:
        out.append(f"| `{r['case']}` | {r['groups']:,} | {r['triangles_bound']:.3g} | {r['triangles_estimate']:.3g} | "
                   f"{r['estimate_bytes'] / 2**20:,.0f} MiB | {r['peak_bytes'] / 2**20:,.0f} MiB | "
                   f"{r['peak_over_estimate']:.2f} |")
    return out + ["", "Raw JSON: `benchmarks/results/clg_budget.json`.", ""]


def _kept_sections(path: Path, generated: set[str]) -> list[str]:
    """The sections of the existing page that no benchmark here generates (written by hand: the
    seeds' tables, CLG, body fill), kept as they are, in their order."""
    if not path.is_file():
        return []
    out, keep = [], False
    for line in path.read_text().splitlines():
        if line.startswith("## "):
            keep = line not in generated
        if keep:
            out.append(line)
    while out and not out[-1].strip():  # the blank lines at the end are added once, not once per run
        out.pop()
    return out + ([""] if out else [])


def write_report() -> Path:
    biq, lil, mesh, becots, ev = (_load(n) for n in ("biq", "lil", "mesh", "becots", "eval"))
    machine = _load("machine") or {}
    lines = ["# Performance", "",
             f"Measured by `make bench` (`benchmarks/run_all.py`) on {machine.get('cores', 2)} cores "
             f"({machine.get('machine', 'this machine')}), {machine.get('date', '')}; every benchmark times its "
             "baseline in the same run. The thesis prototype (Java, i7-7700K) is the bar (SPEC §8): its BIQs "
             "(Table 7.2) ran on one thread, its LiLs (Table 7.1) on 8; the RangeFinder paper's LiLs (Table 1) on "
             "8 threads of an i7-6820HQ.", ""]
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
    curved, startup = _load("curved"), _load("startup")
    if curved:
        plot_curved(curved)
        lines += curved_section(curved)
    if startup:
        lines += startup_section(startup)
    unclean = _load("unclean")
    if unclean:
        plot_unclean(unclean)
        lines += unclean_section(unclean)
    addon = _load("addon")
    if addon:
        plot_addon(addon)
        lines += addon_section(addon)
    presets = _load("presets")
    if presets:
        lines += presets_section(presets)
    clg_budget = _load("clg_budget")
    if clg_budget:
        lines += clg_budget_section(clg_budget)
    for title, name, d in (("BeCOTS RangeFinder", "becots", becots), ("Lazy evaluation", "eval", ev)):
        if d:
            lines += generic_section(title, name, d)
    out = DOCS / "performance.md"
    lines += _kept_sections(out, {x for x in lines if x.startswith("## ")})
    out.write_text("\n".join(lines) + "\n")
    return out


if __name__ == "__main__":
    print(write_report())
