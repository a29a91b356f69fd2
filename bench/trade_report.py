#!/usr/bin/env python3
"""Turns bench_trade's JSON into bench/RESULTS.md and its plots (bench/plots/).

    trade_report.py RESULTS.json OUT.md [--plots DIR] [--log build.log]

Every table comes from the JSON of one run; ratios compare figures measured in
that same run. Lokovic & Veach 2000's published figures are quoted beside ours
where the report reproduces one of their experiments."""
import argparse
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

# Lokovic & Veach 2000, Fig. 7: hair ball (50,000 hairs), deep map 256x256 with
# N samples per pixel vs a normal map with the same number of depth samples.
LV_FIG7 = [  # samples, error, time normal, time deep (s), space normal, deep (MB)
    ("2 × 2", "25.00 %", 34, 45, 0.34, 0.49),
    ("4 × 4", "12.50 %", 39, 46, 1.34, 0.79),
    ("8 × 8", "6.25 %", 60, 45, 5.34, 1.18),
    ("16 × 16", "3.12 %", 145, 46, 21.34, 1.53),
    ("32 × 32", "1.56 %", 554, 46, 85.34, 1.84),
    ("64 × 64", "0.78 %", 2414, 45, 341.34, 2.20),
]


def fit_exponent(xs, ys):
    lx = [math.log(x) for x in xs]
    ly = [math.log(y) for y in ys]
    mx, my = sum(lx) / len(lx), sum(ly) / len(ly)
    sxx = sum((a - mx) ** 2 for a in lx)
    return sum((a - mx) * (b - my) for a, b in zip(lx, ly)) / sxx if sxx else float("nan")


def kib(b):
    return f"{b / 1024:,.1f}"


def ns(seconds):
    return f"{seconds * 1e9:,.0f}"


def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---:" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)



def bias_text(bias):
    """A bias as the report shows it: a number, or "auto" (negative or a string in the JSON)."""
    return "auto" if isinstance(bias, str) or bias < 0 else f"{bias:.3g}"

class Report:
    def __init__(self, data, plots_dir, md_dir):
        self.d = data
        self.plots = plots_dir
        self.rel = os.path.relpath(plots_dir, md_dir)
        self.lines = []
        os.makedirs(plots_dir, exist_ok=True)

    def add(self, *text):
        self.lines.extend(text)

    def figure(self, fig, name, caption):
        path = os.path.join(self.plots, name)
        fig.tight_layout()
        fig.savefig(path, dpi=90)
        plt.close(fig)
        self.add(f"![{caption}]({self.rel}/{name})", "")

    # ---------------------------------------------------------------- sections

    def tolerance_spp(self):
        self.add("## 1. Tolerance × samples per pixel", "")
        self.add("Each map is built with a box filter of width 1 (a pixel is the mean of its own N samples) and "
                 "ε = factor × 0.25/√N. Errors are of bilinear lookups at level 0 at random points where the map "
                 "has content: *vs reference* against a map of the same scene with many more samples and another "
                 "seed (the total error a user sees: sampling noise plus compression), *compression* against "
                 "the uncompressed (ε = 0) map of the same N and seed (bounded by ε). Uncompressed maps are built "
                 "only for small N: they keep every sample's vertices (see *raw samples*).", "")
        for s in self.d["tolerance_spp"]:
            rows = s["rows"]
            self.add(f"### {s['scene']} ({s['resolution']}², reference {s['reference_spp']} spp at "
                     f"ε = {s['reference_tolerance']}, {s['queries']:,} lookups)", "")
            if "reference_error_vs_traced" in s:
                rt = s["reference_error_vs_traced"]
                self.add(f"*Traced truth*: at {s['traced_queries']} pixel centres, the pixel's exact box-filtered "
                         f"visibility estimated with {s['traced_rays_per_query']} rays through the real scene by the "
                         f"Embree reference tracer ({s['traced_seconds']:.1f} s); the reference map itself is off "
                         f"from it by {rt['mean']:.4f} on average (max {rt['max']:.4f}).", "")
            base = {r["spp"]: r for r in rows if r["tolerance_factor"] == 1.0}
            body = []
            for r in rows:
                b = base.get(r["spp"])
                comp = r.get("error_vs_uncompressed")
                body.append([r["spp"], f"{r['tolerance_factor']:g}", f"{r['tolerance']:.4f}",
                             f"{r['build_seconds']:.2f}", kib(r["file_bytes"]),
                             f"{r['file_bytes'] / b['file_bytes']:.2f}" if b else "",
                             f"{r['mean_vertices']:.2f}", ns(r["seconds_per_lookup"]),
                             f"{r['error_vs_reference']['max']:.4f}", f"{r['error_vs_reference']['mean']:.5f}",
                             f"{comp['max']:.4f}" if comp else "–",
                             f"{r['error_vs_traced']['mean']:.4f} / {r['error_vs_traced']['max']:.3f}"
                             if "error_vs_traced" in r else "–", kib(r["raw_sample_bytes"])])
            self.add(table(["N", "factor", "ε", "build s", "file KiB", "size / default ε", "vertices/pixel",
                            "lookup ns", "max err", "mean err", "compression max err", "traced truth mean / max err",
                            "raw samples KiB"], body), "")
            fig, ax = plt.subplots(1, 2, figsize=(11, 4))
            for n in sorted({r["spp"] for r in rows}):
                rs = [r for r in rows if r["spp"] == n]
                ax[0].plot([r["file_bytes"] / 1024 for r in rs], [r["error_vs_reference"]["mean"] for r in rs],
                           "o-", label=f"N={n}")
                ax[1].plot([r["tolerance_factor"] for r in rs], [r["build_seconds"] for r in rs], "o-",
                           label=f"N={n}")
            ax[0].set_xscale("log")
            ax[0].set_yscale("log")
            ax[0].set_xlabel("file size (KiB)")
            ax[0].set_ylabel("mean |error| vs reference")
            ax[0].legend(fontsize=8)
            ax[1].set_yscale("log")
            ax[1].set_xlabel("tolerance factor (× 0.25/√N)")
            ax[1].set_ylabel("build time (s)")
            self.figure(fig, f"tolerance-spp-{s['scene']}.png", f"error against size, {s['scene']}")

    def vertex_growth(self):
        self.add("## 3. Vertex growth (Lokovic & Veach Fig. 8)", "")
        self.add("Mean vertices per non-empty pixel at the default tolerance 0.25/√N, against N, for the maps of "
                 "section 1 (box filter of width 1). LV predict O(N^¼) for piecewise-smooth functions and O(N^½) "
                 "at worst. The builder's default Gaussian filter of width 2 averages more samples per pixel; the "
                 "hair ball's growth with it is measured in [COMPONENTS.md](COMPONENTS.md) (building maps).", "")
        body, fig = [], plt.figure(figsize=(5.5, 4))
        for s in self.d["tolerance_spp"]:
            rs = [r for r in s["rows"] if r["tolerance_factor"] == 1.0]
            xs, ys = [r["spp"] for r in rs], [r["mean_vertices"] for r in rs]
            k = fit_exponent(xs, ys) if len(xs) > 1 else float("nan")
            body.append([s["scene"], " / ".join(f"{y:.2f}" for y in ys), f"{k:.3f}", "0.25", "0.5"])
            plt.loglog(xs, ys, "o-", label=f"{s['scene']} (exponent {k:.2f})")
            if xs:
                plt.loglog(xs, [ys[0] * (x / xs[0]) ** 0.25 for x in xs], ":", color="gray")
        plt.xlabel("samples per pixel N")
        plt.ylabel("mean vertices per pixel")
        plt.legend(fontsize=8)
        n_list = " / ".join(str(r["spp"]) for r in self.d["tolerance_spp"][0]["rows"] if r["tolerance_factor"] == 1.0)
        self.add(table(["scene", f"vertices at N = {n_list}", "fitted exponent", "LV predicted", "worst case"],
                       body), "")
        self.figure(fig, "vertex-growth.png", "vertex growth; dotted: N^1/4 through the first point")
        self.add("Mip pyramid overhead (all levels / level 0, at the default ε; LV §5.3 estimate ≈ 1.55):", "")
        body = []
        for s in self.d["tolerance_spp"]:
            rs = [r for r in s["rows"] if r["tolerance_factor"] == 1.0]
            body.append([s["scene"]] + [f"{r['pyramid_ratio']:.2f}" for r in rs])
        self.add(table(["scene"] + [f"N={r['spp']}" for r in self.d["tolerance_spp"][0]["rows"]
                                    if r["tolerance_factor"] == 1.0], body), "")

    def deep_vs_normal(self):
        s = self.d["deep_vs_normal"]
        self.add("## 2. Deep vs normal shadow maps (Lokovic & Veach Fig. 7)", "")
        self.add(f"Scene {s['scene']}; deep map {s['deep_resolution']}² with N samples per pixel at ε = 0.25/√N "
                 "(half the expected error, as LV); normal (depth) map with the same number of depth samples, "
                 f"{s['deep_resolution']}·√N on a side, filtered by percentage-closer filtering over the N depth "
                 "pixels under one deep pixel (*PCF*), or with N jittered samples (*PCF sampled*, LV's method). Both "
                 "answer at deep-pixel centres and are compared with the reference map's pixel. A depth map keeps "
                 "only the nearest surface, so the hair (opacity 0.5) shadows as if opaque: that bias, not noise, "
                 "dominates its error. Lookup times are per lookup on one thread; space is level 0 of the deep "
                 "file (as LV, without mip-maps) against 4 bytes per depth sample.", "")
        body = []
        for r in s["rows"]:
            dp, nm = r["deep"], r["normal"]
            body.append([r["spp"], f"{100 * r['expected_error']:.2f} %", ns(nm["seconds_per_lookup"]),
                         ns(nm["sampled_seconds_per_lookup"]), ns(dp["seconds_per_lookup"]),
                         f"{nm['seconds_per_lookup'] / dp['seconds_per_lookup']:.1f}",
                         kib(nm["bytes"]), kib(dp["level0_bytes"]), f"{nm['bytes'] / dp['level0_bytes']:.1f}",
                         f"{nm['error']['mean']:.4f}", f"{dp['error']['mean']:.4f}", f"{nm['error']['max']:.3f}",
                         f"{dp['error']['max']:.3f}"])
        self.add(table(["N", "0.5/√N", "PCF ns", "PCF sampled ns", "deep ns", "time normal/deep", "normal KiB",
                        "deep KiB", "space normal/deep", "normal mean err", "deep mean err", "normal max err",
                        "deep max err"], body), "")
        self.add("LV's Fig. 7 for comparison (their renderer, 256² deep maps, times for whole frames):", "")
        self.add(table(["samples", "error", "normal s", "deep s", "normal MB", "deep MB"], LV_FIG7), "")
        fig, ax = plt.subplots(1, 2, figsize=(11, 4))
        xs = [r["spp"] for r in s["rows"]]
        ax[0].loglog(xs, [r["normal"]["bytes"] / 1024 for r in s["rows"]], "o-", label="normal (float32)")
        ax[0].loglog(xs, [r["deep"]["level0_bytes"] / 1024 for r in s["rows"]], "o-", label="deep level 0")
        ax[0].set_xlabel("depth samples per deep pixel N")
        ax[0].set_ylabel("KiB")
        ax[0].legend()
        ax[1].loglog(xs, [r["normal"]["seconds_per_lookup"] * 1e9 for r in s["rows"]], "o-", label="PCF")
        ax[1].loglog(xs, [r["normal"]["sampled_seconds_per_lookup"] * 1e9 for r in s["rows"]], "o-",
                     label="PCF sampled")
        ax[1].loglog(xs, [r["deep"]["seconds_per_lookup"] * 1e9 for r in s["rows"]], "o-", label="deep")
        ax[1].set_xlabel("N")
        ax[1].set_ylabel("ns per lookup")
        ax[1].legend()
        self.figure(fig, "deep-vs-normal.png", "space and lookup time, deep vs normal shadow maps")

    def filter_width(self):
        s = self.d.get("filter_width") or {}
        if not s:
            return
        self.add("## 4. Filter width (Lokovic & Veach Fig. 9)", "")
        self.add(f"Scene {s['scene']} at N = {s['spp']}: deep map {s['deep_resolution']}² with mip-maps (level "
                 "auto, trilinear) and forced to level 0; normal map "
                 f"{s['normal_resolution']}² with exact PCF over the whole footprint and with 8 × 8 jittered "
                 "samples (LV's setting). Nanoseconds per box-filtered lookup, one thread, warm cache.", "")
        rows = s["rows"]
        body = [[f"{r['width']:g}", f"{r['width_fraction']:.3f}", ns(r["deep_mipmapped_seconds"]),
                 ns(r["deep_level0_seconds"]), ns(r["pcf_exact_seconds"]), ns(r["pcf_8x8_seconds"]),
                 f"{r['deep_mipmapped_seconds'] / rows[0]['deep_mipmapped_seconds']:.2f}",
                 f"{r['pcf_exact_seconds'] / rows[0]['pcf_exact_seconds']:.0f}"] for r in rows]
        self.add(table(["width (deep px)", "fraction of map", "deep mip ns", "deep level 0 ns", "PCF exact ns",
                        "PCF 8×8 ns", "deep mip / width 1", "PCF exact / width 1"], body), "")
        fig = plt.figure(figsize=(5.5, 4))
        xs = [r["width_fraction"] for r in rows]
        for key, label in [("deep_mipmapped_seconds", "deep, mip-mapped"), ("deep_level0_seconds", "deep, level 0"),
                           ("pcf_exact_seconds", "PCF exact"), ("pcf_8x8_seconds", "PCF 8×8")]:
            plt.loglog(xs, [r[key] * 1e9 for r in rows], "o-", label=label)
        plt.xlabel("filter width / map width")
        plt.ylabel("ns per lookup")
        plt.legend(fontsize=8)
        self.figure(fig, "filter-width.png", "lookup time against filter width")

    def storage(self):
        s = self.d["storage"]
        self.add("## 5. Storage against OpenEXR deep", "")
        self.add(f"Scene {s['scene']} at {s['resolution']}², N = {s['spp']} (ε = {s['tolerance']:.4f}). One build "
                 "hands its raw sample rays to an OpenEXR deep scanline file (ZIPS; float Z, ZBack, A; every surface "
                 "hit a point sample with A = opacity/N, every volume step a volumetric sample), as a deep renderer "
                 "writes them, and writes our `.dsm`. Read time: every sample of the EXR "
                 "(`DeepScanLineInputFile`) against every pixel function of our level 0 (all tiles decoded), best "
                 "of three.", "")
        self.add(table(["", "OpenEXR deep", ".dsm (all levels)", ".dsm level 0", "ratio EXR / .dsm"], [
            ["bytes", f"{s['exr_bytes']:,}", f"{s['dsm_bytes']:,}", f"{s['dsm_level0_bytes']:,}",
             f"{s['exr_bytes'] / s['dsm_bytes']:.1f}"],
            ["samples / vertices", f"{s['raw_samples']:,}", "", f"{s['dsm_vertices']:,}",
             f"{s['raw_samples'] / max(1, s['dsm_vertices']):.1f}"],
            ["read ms", f"{s['exr_read_seconds'] * 1e3:.1f}", "", f"{s['dsm_read_seconds'] * 1e3:.1f}",
             f"{s['exr_read_seconds'] / max(1e-12, s['dsm_read_seconds']):.1f}"]]), "")
        self.add(f"Our mip pyramid costs {s['dsm_pyramid_ratio']:.2f}× level 0 here (LV §5.3: ≈ 1.55).", "")

    def soft_shadows(self):
        soft = self.d["soft_shadows"]
        self.add("## 7. Area-light soft shadows: MTSM ray tracing vs PCF vs ray tracing the scene", "")
        self.add("`bench/soft_shadows` (issue: Xie et al. 2007 Tables 1-2). Per scene one map, built for the "
                 "largest light (push-back of Xie eq. 4) with MTSM layers and counts; a viewing camera finds the "
                 "receivers (every surface it sees) with the reference tracer; each receiver's shadow is computed "
                 "(a) by tracing the light samples' rays through the map as an MTSM, (b) by the PCF-based method "
                 "from the same map, (c) by tracing the same rays through the real scene with Embree. Errors are "
                 "the mean ± standard deviation over receivers of |method − (c)|; times are whole frames on "
                 f"{soft['threads']} threads. Light radii are 2 %, 5 % and 12 % of the light's distance to the "
                 "scene.", "")
        for sc in soft["scenes"]:
            m = sc["map"]
            filt = f"{m['filter']} {m['filter_width']:g}, tolerance {m['tolerance']:.3g}, " if "filter" in m else ""
            self.add(f"### {sc['scene']} (map {m['resolution']}², {m['spp']} spp, {filt}{m['layers']} layers, "
                     f"{kib(m['file_bytes'])} KiB; image {sc['image']['width']}×{sc['image']['height']}; "
                     f"bias {bias_text(sc['bias'])}, z threshold {sc['z_threshold']:.3g})", "")
            body = []
            for r in sc["rows"]:
                me, pe = r["mtsm_error"], r["pcf_error"]
                body.append([r["radius"], r["samples"], f"{me['mean']:.4f} ± {me['stddev']:.4f}",
                             f"{pe['mean']:.4f} ± {pe['stddev']:.4f}",
                             f"{me['mean'] / pe['mean']:.2f}" if pe["mean"] > 0 else "–",
                             f"{r['reference_seconds']:.2f}", f"{r['mtsm_seconds']:.2f}", f"{r['pcf_seconds']:.3f}",
                             f"{r['reference_seconds'] / r['mtsm_seconds']:.1f}"])
            self.add(table(["light", "N", "MTSM error", "PCF error", "MTSM / PCF error", "reference s", "MTSM s",
                            "PCF s", "reference / MTSM time"], body), "")
            self.add(f"![{sc['scene']}: reference, MTSM, PCF, MTSM − reference, PCF − reference; rows small, "
                     f"medium, large light]({self.rel}/{sc['sheet']})", "")
            self.add("Columns: reference, MTSM, PCF, then the differences MTSM − reference and PCF − reference "
                     "(×4; red: too bright, blue: too dark); rows: small, medium, large light; "
                     f"N = {sc['rows'][-1]['samples']}.", "")
            if "ray_speed" in sc:
                r = sc["ray_speed"]
                self.add(f"A ray through the map against a ray through the scene (one thread, medium light, 64 rays "
                         f"for each of {r['receivers']} receivers, classification off so every ray is traced; the "
                         "same light samples; the receivers in slices, each traced through the map and then through the "
                         "scene): map "
                         f"{r['map_rays_per_second'] / 1e6:.2f} M rays/s ({r['nodes_per_ray']:.1f} nodes and "
                         f"{r['pixels_per_ray']:.1f} pixels per ray, "
                         f"{100 * r['rays_proven_opaque'] / max(1, r['rays']):.1f} % of the rays proven opaque), "
                         f"Embree {r['scene_rays_per_second'] / 1e6:.2f} M rays/s: "
                         f"**{r['map_over_scene']:.2f}×**.", "")
            if "scaling" in sc:
                body = [[f"{r['resolution']}²", f"{r['walk']['pixels_per_ray']:.1f}",
                         f"{r['walk']['microseconds_per_ray']:.2f}", f"{r['hierarchy']['pixels_per_ray']:.1f}",
                         f"{r['hierarchy']['nodes_per_ray']:.1f}", f"{r['hierarchy']['microseconds_per_ray']:.2f}",
                         f"{r['walk']['microseconds_per_ray'] / r['hierarchy']['microseconds_per_ray']:.1f}"]
                        + ([f"{1e3 * r['first_query']['median_seconds']:.1f}",
                            f"{r['first_query']['mean_tiles_built']:.0f} of {r['first_query']['tiles']}"]
                           if "first_query" in r else [])
                        for r in sc["scaling"]]
                first = "first_query" in sc["scaling"][0]
                self.add("Cost per ray against the map's resolution (Xie §4.3; medium light, 64 rays per receiver, "
                         f"{sc['scaling'][0]['receivers']} receivers, classification off, one thread): walking every "
                         "pixel a ray crosses against the min/max depth hierarchy"
                         + ("; and the time from opening the map to the first answer (defaults, 64 rays; median "
                            "over receivers across the view, each on a freshly opened map) with the tiles whose "
                            "depth pyramids it built." if first else "."), "")
                self.add(table(["map", "walk pixels/ray", "walk µs/ray", "hierarchy pixels/ray", "hierarchy nodes/ray",
                                "hierarchy µs/ray", "walk / hierarchy time"]
                               + (["first query ms", "pyramids built"] if first else []), body), "")
            if "knobs" in sc:
                body = [[k["knob"], f"{k['value']:.4g}", k["samples"], k["layers"] or "all", bias_text(k["bias"]),
                         f"{k['error']['mean']:.4f} ± {k['error']['stddev']:.4f}", f"{k['mtsm_seconds']:.2f}",
                         f"{k['reference_seconds'] / k['mtsm_seconds']:.1f}"] for k in sc["knobs"]]
                self.add("The knobs at the medium light (one changed at a time from the defaults above):", "")
                self.add(table(["knob", "value", "N", "K", "bias", "MTSM error", "MTSM s", "reference / MTSM time"],
                               body), "")
            if "bias_study" in sc:
                b = sc["bias_study"]
                self.add("The automatic bias against constants (medium light, 64 rays; the reference's fully lit "
                         f"receivers, {b['lit_receivers']}, that read below 0.9 count as self-shadowed):", "")
                body = [[f"{c['bias']:.4g}", f"{c['error']['mean']:.4f} ± {c['error']['stddev']:.4f}",
                         f"{c['error']['mean'] / b['best_error']:.2f}", c["lit_but_dark"]] for c in b["constants"]]
                for key, label in (("auto", "auto"), ("auto_normals", "auto + normals")):
                    a = b[key]
                    body.append([f"**{label}**", f"{a['error']['mean']:.4f} ± {a['error']['stddev']:.4f}",
                                 f"**{a['ratio_to_best']:.2f}**", a["lit_but_dark"]])
                self.add(table(["bias", "MTSM error", "error / best constant's", "lit receivers below 0.9"], body),
                         "")

    def cache_budget(self):
        s = self.d["cache_budget"]
        self.add("## 6. Cache budget", "")
        self.add(f"Scene {s['scene']}, {s['resolution']}² map in {s['tile_size']}² tiles ({s['tiles']} tiles in all "
                 f"levels, {kib(s['decoded_bytes'])} KiB decoded); one bilinear lookup per pixel "
                 f"({s['queries']:,}) in scanline order and shuffled, through a fresh cache of the given share of "
                 "the decoded size.", "")
        rows = s["rows"]
        best = max(r["lookups_per_second"] for r in rows)
        body = []
        for f in sorted({r["budget_fraction"] for r in rows}):
            sc = next(r for r in rows if r["budget_fraction"] == f and r["order"] == "scanline")
            rd = next(r for r in rows if r["budget_fraction"] == f and r["order"] == "random")
            body.append([f"{100 * f:g} %", f"{sc['lookups_per_second']:,.0f}", sc["tiles_read"],
                         f"{rd['lookups_per_second']:,.0f}", rd["tiles_read"],
                         f"{sc['lookups_per_second'] / rd['lookups_per_second']:.1f}"])
        self.add(table(["budget", "scanline lookups/s", "scanline tiles read", "random lookups/s",
                        "random tiles read", "scanline / random"], body), "")
        fig = plt.figure(figsize=(5.5, 4))
        for order in ("scanline", "random"):
            rs = [r for r in rows if r["order"] == order]
            plt.semilogx([100 * r["budget_fraction"] for r in rs], [r["lookups_per_second"] / best for r in rs],
                         "o-", label=order)
        plt.xlabel("cache budget (% of decoded map)")
        plt.ylabel("throughput / best")
        plt.legend()
        self.figure(fig, "cache-budget.png", "throughput against cache budget")

    def render(self):
        m = self.d["machine"]
        self.add("# The trade: what each knob costs", "")
        self.add("Generated by `scripts/bench-trade` (bench/trade/, bench/trade_report.py) from one run; do not "
                 "edit by hand. Component benchmarks (compressor against memcpy, sweep against the naive "
                 "average, lookups and file reading) are in [COMPONENTS.md](COMPONENTS.md).", "")
        if self.d.get("smoke"):
            self.add("**Smoke run: tiny maps, the numbers are not measurements.**", "")
        self.add(f"Machine: {m['cpu']}, {m['hardware_threads']} hardware threads, gcc {m['compiler']}, "
                 f"{m['date']}; whole run {self.d['total_seconds']:.0f} s. Builds use all threads; lookups one.", "")
        self.summary()
        self.tolerance_spp()
        self.deep_vs_normal()
        self.vertex_growth()
        self.filter_width()
        if "storage" in self.d:
            self.storage()
        self.cache_budget()
        if "soft_shadows" in self.d:
            self.soft_shadows()
        return "\n".join(self.lines) + "\n"

    def summary(self):
        self.add("## Headlines", "")
        s = self.d["deep_vs_normal"]["rows"]
        if s:
            last = s[-1]
            self.add(f"- At N = {last['spp']} depth samples per deep pixel, the normal shadow map takes "
                     f"{last['normal']['bytes'] / last['deep']['level0_bytes']:.1f}× the space of the deep map's "
                     f"level 0 and its PCF lookup {last['normal']['seconds_per_lookup'] / last['deep']['seconds_per_lookup']:.1f}× "
                     f"the time; mean error {last['normal']['error']['mean']:.4f} vs {last['deep']['error']['mean']:.4f}.")
        fw = self.d.get("filter_width", {}).get("rows", [])
        if fw:
            self.add(f"- Widening the filter {fw[-1]['width'] / fw[0]['width']:.0f}× changes the mip-mapped deep "
                     f"lookup time {fw[-1]['deep_mipmapped_seconds'] / fw[0]['deep_mipmapped_seconds']:.2f}×, the "
                     f"exact PCF's {fw[-1]['pcf_exact_seconds'] / fw[0]['pcf_exact_seconds']:.0f}×.")
        for t in self.d["tolerance_spp"]:
            rs = [r for r in t["rows"] if r["tolerance_factor"] == 1.0]
            if len(rs) > 1:
                k = fit_exponent([r["spp"] for r in rs], [r["mean_vertices"] for r in rs])
                self.add(f"- {t['scene']}: vertices per pixel grow as N^{k:.2f} (LV: N^0.25); at N = "
                         f"{rs[-1]['spp']} the file is {rs[-1]['raw_sample_bytes'] / rs[-1]['file_bytes']:.0f}× "
                         "smaller than the raw samples.")
        if "soft_shadows" in self.d:
            for sc in self.d["soft_shadows"]["scenes"]:
                r = [x for x in sc["rows"] if x["radius"] == "medium"][-1]
                speed = (f"; a ray through the map {sc['ray_speed']['map_over_scene']:.2f}× as fast as one through "
                         "the scene" if "ray_speed" in sc else "")
                self.add(f"- Soft shadows, {sc['scene']} (medium light, N = {r['samples']}): MTSM error "
                         f"{r['mtsm_error']['mean']:.4f} = {r['mtsm_error']['mean'] / r['pcf_error']['mean']:.2f}× "
                         f"PCF's, {r['reference_seconds'] / r['mtsm_seconds']:.1f}× faster than ray tracing the scene"
                         f"{speed}.")
        if "storage" in self.d:
            st = self.d["storage"]
            self.add(f"- OpenEXR deep (ZIPS) of the raw samples: {st['exr_bytes'] / st['dsm_bytes']:.1f}× our file.")
        self.add("")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("results")
    p.add_argument("out")
    p.add_argument("--plots", default=None)
    p.add_argument("--soft", default=None, help="bench_soft_shadows JSON (section 7)")
    a = p.parse_args()
    with open(a.results) as f:
        data = json.load(f)
    if a.soft:
        with open(a.soft) as f:
            data["soft_shadows"] = json.load(f)
    md_dir = os.path.dirname(os.path.abspath(a.out))
    plots = a.plots or os.path.join(md_dir, "plots")
    text = Report(data, plots, md_dir).render()
    with open(a.out, "w") as f:
        f.write(text)
    print(f"wrote {a.out} and plots in {plots}", file=sys.stderr)


if __name__ == "__main__":
    main()
