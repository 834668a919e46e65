#!/usr/bin/env python3
"""Charts and tables of the centroid study (issue 16, item 3).

    cargo run --release --example centroid_study -- docs/study/centroid_study.csv
    python3 scripts/plot_centroid_study.py docs/study/centroid_study.csv [--out docs/study]

Reads the CSV of examples/centroid_study.rs and writes into --out:
  fig_centroid_sigma.png     error/CRB against PSF sigma, CoG and ML, one line per SNR
  fig_centroid_snr.png       error/CRB against SNR at sigma = 0.8 and 1.2 px (and the detected share)
  fig_centroid_phase.png     bias and error/CRB against sub-pixel phase at sigma = 0.5 and 1.2 px
  fig_centroid_error_px.png  RMS error (px) against sigma with the CRB: at fixed SNR and at fixed flux
and prints the optimum sigma of each estimator and markdown tables (numpy and matplotlib only).

A point enters a chart or an optimum only when at least MIN_DETECTED (90 %) of its stars were
detected: below that the survivors are the stars that noise made brighter, and their errors
say little. Tables show every point, with its detected share.
"""

import argparse
import csv
import math
import os
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

MIN_DETECTED = 0.9
FADED = 0.2  # fig_centroid_sigma also shows points with 20-90 % detected, faded
CEIL = 1.15  # the "ML within 15 % of the CRB"
SNR_COLOURS = {10: "tab:purple", 20: "tab:blue", 50: "tab:green", 100: "tab:red"}
FLUX_COLOURS = {500: "tab:purple", 1000: "tab:blue", 3000: "tab:green", 10000: "tab:red"}
STYLE = {"cog": dict(ls="--", marker="s", mfc="none"), "ml": dict(ls="-", marker="o")}
LABEL = {"cog": "CoG", "ml": "ML", "ml_settled": "ML (settled fits)"}


def load(path):
    rows = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            for k, v in r.items():
                if k in ("sweep", "estimator", "phase_px"):
                    continue
                r[k] = float(v) if v != "" else math.nan
            r["phase"] = math.nan if r["phase_px"] == "random" else float(r["phase_px"])
            r["snr_r"] = round(r["snr"])
            r["det"] = r["detected"] / r["stars"]
            rows.append(r)
    return rows


def select(rows, **kw):
    out = [r for r in rows if all(r[k] == v for k, v in kw.items())]
    return out


def good(r):
    return r["det"] >= MIN_DETECTED


def series(rows, key, value):
    rows = sorted(rows, key=lambda r: r[key])
    return np.array([r[key] for r in rows]), np.array([r[value] for r in rows])


def fig_sigma(rows, out):
    fig, ax = plt.subplots(figsize=(8, 5.2))
    for snr, c in SNR_COLOURS.items():
        for est in ("cog", "ml"):
            every = select(rows, sweep="sigma", estimator=est, snr_r=snr)
            pts = [r for r in every if good(r)]
            faint = [r for r in every if FADED <= r["det"] < MIN_DETECTED]
            label = f"{LABEL[est]}, SNR {snr}"
            if faint:
                x, y = series([r for r in every if r["det"] >= FADED], "sigma_px", "err_over_crb")
                ax.plot(x, y, color=c, alpha=0.35, label=None if pts else label + " (faded)", **STYLE[est])
            if pts:
                x, y = series(pts, "sigma_px", "err_over_crb")
                ax.plot(x, y, color=c, label=label, **STYLE[est])
    ax.axhline(1.0, color="k", lw=0.8)
    ax.axhline(CEIL, color="k", lw=0.8, ls=":", label="CRB + 15 %")
    ax.set_yscale("log")
    ax.set_yticks([0.7, 1, 1.15, 1.5, 2, 3, 5])
    ax.get_yaxis().set_major_formatter(matplotlib.ticker.ScalarFormatter())
    ax.get_yaxis().set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("PSF sigma (px)")
    ax.set_ylabel("RMS per-axis error / sqrt(CRB)")
    ax.set_title(
        "gpustar centroids against the Cramér–Rao bound (random sub-pixel phase)\n"
        "faded: 20–90 % of the stars detected (survivors biased bright)",
        fontsize=10,
    )
    ax.grid(alpha=0.3, which="both")
    ax.legend(ncol=2, fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig_centroid_sigma.png"), dpi=120)
    plt.close(fig)


def fig_snr(rows, out):
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), sharey=True)
    for ax, s in zip(axes, (0.8, 1.2)):
        for est, c in (("cog", "tab:orange"), ("ml", "tab:blue")):
            pts = [r for r in select(rows, sweep="snr", estimator=est, sigma_px=s) if good(r)]
            x, y = series(pts, "snr", "err_over_crb")
            ax.plot(x, y, color=c, label=f"{LABEL[est]}, bias 100 ADU", **STYLE[est])
            pts = [r for r in select(rows, sweep="bias0", estimator=est, sigma_px=s) if good(r)]
            x, y = series(pts, "snr", "err_over_crb")
            ax.plot(x, y, color=c, ls="none", marker="x", ms=8, label=f"{LABEL[est]}, bias 0")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.axhline(CEIL, color="k", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_xlabel("SNR = N / sqrt(N + 4πσ²(b + σr²))")
        ax.set_title(f"sigma = {s} px")
        ax.grid(alpha=0.3, which="both")
        tw = ax.twinx()
        pts = select(rows, sweep="snr", estimator="cog", sigma_px=s)
        x, y = series(pts, "snr", "det")
        tw.plot(x, 100 * y, color="0.6", lw=1, label="detected (%)")
        tw.set_ylim(0, 105)
        tw.set_ylabel("stars detected (%)", color="0.5")
        if s == 0.8:
            tw.set_yticklabels([])
            tw.set_ylabel("")
    axes[0].set_ylabel("RMS per-axis error / sqrt(CRB)")
    axes[0].legend(fontsize=8)
    fig.suptitle("Error / CRB against SNR (points with < 90 % detected left out)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig_centroid_snr.png"), dpi=120)
    plt.close(fig)


def fig_phase(rows, out):
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex=True)
    for col, s in enumerate((0.5, 1.2)):
        for snr, c in ((20, "tab:blue"), (100, "tab:red")):
            for est in ("cog", "ml"):
                pts = select(rows, sweep="phase", estimator=est, sigma_px=s, snr_r=snr)
                x, b = series(pts, "phase", "bias_x_px")
                _, by = series(pts, "phase", "bias_y_px")
                _, e = series(pts, "phase", "err_over_crb")
                kw = dict(color=c, label=f"{LABEL[est]}, SNR {snr}", **STYLE[est])
                axes[0, col].plot(x, 0.5 * (b + by), **kw)
                axes[1, col].plot(x, e, **kw)
        axes[0, col].axhline(0, color="k", lw=0.8)
        axes[1, col].axhline(1, color="k", lw=0.8)
        axes[1, col].axhline(CEIL, color="k", lw=0.8, ls=":")
        axes[0, col].set_title(f"sigma = {s} px")
        axes[1, col].set_xlabel("sub-pixel phase (px, the same in x and y; 0 = pixel centre)")
        for a in axes[:, col]:
            a.grid(alpha=0.3)
    axes[0, 0].set_ylabel("mean error (px), x and y averaged")
    axes[1, 0].set_ylabel("RMS per-axis error / sqrt(CRB)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Sub-pixel phase: bias and error / CRB")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig_centroid_phase.png"), dpi=120)
    plt.close(fig)


def fig_error_px(rows, out):
    fig, axes = plt.subplots(1, 2, figsize=(12, 5), sharey=True)
    panels = (
        (axes[0], "sigma", "snr_r", SNR_COLOURS, "SNR {}", "at a fixed SNR"),
        (axes[1], "flux", "signal_e", FLUX_COLOURS, "N = {} e⁻", "at a fixed signal N"),
    )
    for ax, sweep, key, colours, fmt, title in panels:
        for v, c in colours.items():
            for est in ("cog", "ml"):
                pts = [r for r in select(rows, sweep=sweep, estimator=est, **{key: v}) if good(r)]
                if not pts:
                    continue
                x, y = series(pts, "sigma_px", "rms_err_px")
                lab = f"{LABEL[est]}, {fmt.format(v)}"
                ax.plot(x, y, color=c, label=lab, **STYLE[est])
            pts = select(rows, sweep=sweep, estimator="cog", **{key: v})
            x, y = series(pts, "sigma_px", "crb_px")
            ax.plot(x, y, color=c, ls=":", lw=2, label=f"CRB, {fmt.format(v)}")
        ax.set_yscale("log")
        ax.set_xlabel("PSF sigma (px)")
        ax.set_title(f"RMS per-axis error {title} (points with < 90 % detected left out)", fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, ncol=3)
    axes[0].set_ylabel("RMS per-axis error (px)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig_centroid_error_px.png"), dpi=120)
    plt.close(fig)


def optimum(rows, sweep, key, value, est):
    pts = [r for r in select(rows, sweep=sweep, estimator=est, **{key: value}) if good(r)]
    if not pts:
        return None
    best = min(pts, key=lambda r: r["rms_err_px"])
    return best["sigma_px"], best["rms_err_px"]


def crb_optimum(rows, sweep, key, value):
    pts = select(rows, sweep=sweep, estimator="cog", **{key: value})
    best = min(pts, key=lambda r: r["crb_px"])
    return best["sigma_px"], best["crb_px"]


def f3(v):
    return "–" if v is None or math.isnan(v) else f"{v:.3f}"


def f2(v):
    return "–" if v is None or math.isnan(v) else f"{v:.2f}"


def tables(rows):
    out = []
    p = out.append
    by = defaultdict(dict)
    for r in rows:
        by[(r["sweep"], r["sigma_px"], r["snr_r"], r["phase_px"], r["signal_e"])][r["estimator"]] = r

    p("### Optimum PSF width (smallest RMS error in px; points with >= 90 % detected)\n")
    p("| set | CoG: sigma (px), error (px) | ML: sigma, error | CRB: sigma, bound (px) |")
    p("|---|---|---|---|")
    for sweep, key, values, fmt in (
        ("sigma", "snr_r", (10, 20, 50, 100), "fixed SNR {}"),
        ("flux", "signal_e", (500, 1000, 3000, 10000), "fixed N = {} e⁻"),
    ):
        for v in values:
            cells = []
            for est in ("cog", "ml"):
                o = optimum(rows, sweep, key, v, est)
                cells.append("–" if o is None else f"{o[0]:g}, {o[1]:.4f}")
            c = crb_optimum(rows, sweep, key, v)
            p(f"| {fmt.format(v)} | {cells[0]} | {cells[1]} | {c[0]:g}, {c[1]:.4f} |")

    p("\n### Error / CRB against sigma (sweep `sigma`, random phase): CoG / ML (robust ML), detected %\n")
    snrs = (10, 20, 50, 100)
    p("| sigma (px) | " + " | ".join(f"SNR {s}" for s in snrs) + " |")
    p("|---|" + "---|" * len(snrs))
    for s in sorted({r["sigma_px"] for r in select(rows, sweep="sigma")}):
        cells = []
        for snr in snrs:
            [c] = select(rows, sweep="sigma", estimator="cog", sigma_px=s, snr_r=snr)
            [m] = select(rows, sweep="sigma", estimator="ml", sigma_px=s, snr_r=snr)
            fb = m["ml_fallbacks"] / max(m["detected"], 1)
            cells.append(
                f"{f2(c['err_over_crb'])} / {f2(m['err_over_crb'])} ({f2(m['robust_over_crb'])}), "
                f"{100 * c['det']:.0f} %" + (f", fb {100 * fb:.0f} %" if fb >= 0.01 else "")
            )
        p(f"| {s:g} | " + " | ".join(cells) + " |")
    p("\n(fb: share of the detected stars where the ML fit did not settle and the CoG stands.)")

    p("\n### SNR sweep (random phase): RMS error (px), CRB (px), error / CRB\n")
    p("| sigma | SNR | N (e⁻) | detected | CoG RMS | ML RMS | CRB | CoG/CRB | ML/CRB | ML robust/CRB |")
    p("|---|---|---|---|---|---|---|---|---|---|")
    for s in (0.8, 1.2):
        for c in sorted(select(rows, sweep="snr", estimator="cog", sigma_px=s), key=lambda r: r["snr"]):
            [m] = select(rows, sweep="snr", estimator="ml", sigma_px=s, snr_r=c["snr_r"])
            p(
                f"| {s:g} | {c['snr_r']} | {c['signal_e']:.0f} | {100 * c['det']:.0f} % | "
                f"{f3(c['rms_err_px'])} | {f3(m['rms_err_px'])} | {f3(c['crb_px'])} | "
                f"{f2(c['err_over_crb'])} | {f2(m['err_over_crb'])} | {f2(m['robust_over_crb'])} |"
            )

    p("\n### Sub-pixel phase: mean error (px, x and y averaged) and error / CRB\n")
    p("| sigma | SNR | phase (px) | CoG bias | CoG/CRB | ML bias | ML/CRB | ML fallbacks |")
    p("|---|---|---|---|---|---|---|---|")
    for s in (0.5, 1.2):
        for snr in (20, 100):
            for c in sorted(select(rows, sweep="phase", estimator="cog", sigma_px=s, snr_r=snr), key=lambda r: r["phase"]):
                [m] = select(rows, sweep="phase", estimator="ml", sigma_px=s, snr_r=snr, phase=c["phase"])
                cb = 0.5 * (c["bias_x_px"] + c["bias_y_px"])
                mb = 0.5 * (m["bias_x_px"] + m["bias_y_px"])
                p(
                    f"| {s:g} | {snr} | {c['phase']:g} | {cb:+.4f} | {f2(c['err_over_crb'])} | "
                    f"{mb:+.4f} | {f2(m['err_over_crb'])} | {m['ml_fallbacks']:.0f} |"
                )

    p("\n### Fixed signal N (random phase): RMS error (px) CoG / ML / CRB, detected %\n")
    ns = (500, 1000, 3000, 10000)
    p("| sigma (px) | " + " | ".join(f"N = {n}" for n in ns) + " |")
    p("|---|" + "---|" * len(ns))
    for s in sorted({r["sigma_px"] for r in select(rows, sweep="flux")}):
        cells = []
        for n in ns:
            [c] = select(rows, sweep="flux", estimator="cog", sigma_px=s, signal_e=n)
            [m] = select(rows, sweep="flux", estimator="ml", sigma_px=s, signal_e=n)
            cells.append(
                f"{f3(c['rms_err_px'])} / {f3(m['rms_err_px'])} / {f3(c['crb_px'])}, {100 * c['det']:.0f} %"
            )
        p(f"| {s:g} | " + " | ".join(cells) + " |")

    p("\n### Bias 0 ADU against 100 ADU (ML error / CRB; gpustar's fit weighs pixels with the level in ADU)\n")
    p("| sigma | SNR | CoG/CRB bias 100 | CoG/CRB bias 0 | ML/CRB bias 100 | ML/CRB bias 0 |")
    p("|---|---|---|---|---|---|")
    for s in (0.8, 1.2):
        for m0 in sorted(select(rows, sweep="bias0", estimator="ml", sigma_px=s), key=lambda r: r["snr"]):
            snr = m0["snr_r"]
            [c0] = select(rows, sweep="bias0", estimator="cog", sigma_px=s, snr_r=snr)
            [c1] = select(rows, sweep="snr", estimator="cog", sigma_px=s, snr_r=snr)
            [m1] = select(rows, sweep="snr", estimator="ml", sigma_px=s, snr_r=snr)
            p(
                f"| {s:g} | {snr} | {f2(c1['err_over_crb'])} | {f2(c0['err_over_crb'])} | "
                f"{f2(m1['err_over_crb'])} | {f2(m0['err_over_crb'])} |"
            )

    p("\n### Key figures: error / CRB at sigma 0.8 and 1.2 px (sweep `snr`)\n")
    p("| sigma | SNR | CoG/CRB | ML/CRB | ML RMS / CoG RMS |")
    p("|---|---|---|---|---|")
    for s in (0.8, 1.2):
        for snr in (20, 50, 100):
            [c] = select(rows, sweep="snr", estimator="cog", sigma_px=s, snr_r=snr)
            [m] = select(rows, sweep="snr", estimator="ml", sigma_px=s, snr_r=snr)
            p(
                f"| {s:g} | {snr} | {f2(c['err_over_crb'])} | {f2(m['err_over_crb'])} | "
                f"{m['rms_err_px'] / c['rms_err_px']:.2f} |"
            )

    p("\n### Check: ML within 15 % of the CRB at SNR >= 20 (sweeps `sigma` and `snr`)\n")
    ok, bad = [], []
    for m in rows:
        if m["estimator"] != "ml" or m["sweep"] not in ("sigma", "snr") or m["snr"] < 19.99:
            continue
        (ok if m["err_over_crb"] <= CEIL else bad).append(m)
    p(f"{len(ok)} of {len(ok) + len(bad)} points pass.")
    for m in sorted(bad, key=lambda r: (r["sigma_px"], r["snr"])):
        p(
            f"- fails: sweep {m['sweep']}, sigma {m['sigma_px']:g}, SNR {m['snr_r']}: "
            f"ML/CRB {f2(m['err_over_crb'])} (robust {f2(m['robust_over_crb'])}; "
            f"settled fits only: {f2(by_settled(rows, m))}), "
            f"{m['ml_fallbacks']:.0f} fallbacks, {m['duplicates']:.0f} duplicates, "
            f"{m['false_detections']:.0f} false detections of {m['detected']:.0f} stars detected"
        )
    return "\n".join(out)


def by_settled(rows, m):
    [s] = select(
        rows, sweep=m["sweep"], estimator="ml_settled", sigma_px=m["sigma_px"], snr_r=m["snr_r"]
    )
    return s["err_over_crb"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csv")
    ap.add_argument("--out", default="docs/study")
    a = ap.parse_args()
    rows = load(a.csv)
    os.makedirs(a.out, exist_ok=True)
    fig_sigma(rows, a.out)
    fig_snr(rows, a.out)
    fig_phase(rows, a.out)
    fig_error_px(rows, a.out)
    print(tables(rows))


if __name__ == "__main__":
    main()
