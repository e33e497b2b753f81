"""Reruns Table 1 of Han, Jureczka & Ochal (2020) through the service: the convergence study
in h at k = 1/128 against the reference h = k = 1/128 (the built-in study "paper-table-1"),
then plots the errors at T against h on log-log axes with slope-1 and slope-2 guides, next to
the paper's own values.

    pip install "./clients/python[all]"
    cargo run --release &                    # the service on 127.0.0.1:8080
    python clients/python/examples/convergence.py --out convergence.png
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")  # a file, no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from contact_sim import Client  # noqa: E402

# Table 1 of the paper: relative errors at T of w (in |.|_V) and of ζ (in |.|_Z0).
PAPER_H = [1 / 2, 1 / 4, 1 / 8, 1 / 16, 1 / 32]
PAPER_ERR_W = [3.4889e-1, 2.2027e-1, 1.2745e-1, 7.2811e-2, 3.9967e-2]
PAPER_ERR_ZETA = [8.7595e-2, 4.3672e-2, 1.7248e-2, 6.1124e-3, 2.1316e-3]


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    ap.add_argument("--url", default="http://127.0.0.1:8080", help="the service")
    ap.add_argument("--token", default=None, help="API token (sent as a Bearer token)")
    ap.add_argument("--out", default="convergence.png", help="the PNG to write")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = ap.parse_args()

    with Client(args.url, token=args.token) as client:
        job = client.submit({"study": {"preset": "paper-table-1"}})
        job.wait(progress=not args.no_progress)
        df = job.table()
        print(job.table_text())

    h = df["h"].to_numpy()
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=120)
    ax.loglog(h, df["err_w"], "o-", color="C0", label="w (this service)")
    ax.loglog(h, df["err_zeta"], "s-", color="C1", label="ζ (this service)")
    ax.loglog(PAPER_H, PAPER_ERR_W, "o", mfc="none", color="C0", alpha=0.6, label="w (paper)")
    ax.loglog(PAPER_H, PAPER_ERR_ZETA, "s", mfc="none", color="C1", alpha=0.6, label="ζ (paper)")
    # Slope guides through the finest level, a little below the data.
    for slope, err, style in ((1, df["err_w"], ":"), (2, df["err_zeta"], "--")):
        anchor = 0.5 * float(err.iloc[-1])
        guide = anchor * (h / h[-1]) ** slope
        ax.loglog(h, guide, style, color="grey", label=f"slope {slope}")
    ax.set_xlabel("h")
    ax.set_ylabel(r"relative error at T: w in $|\cdot|_V$, ζ in $|\cdot|_{Z_0}$")
    ref = df.attrs["reference"]
    ax.set_title(
        f"Table 1: k = 1/{round(1 / df['k'].iloc[0])}, reference h = k = 1/{round(1 / ref['h'])}\n"
        f"least-squares orders: w {df.attrs['lsq_order_w']:.2f}, ζ {df.attrs['lsq_order_zeta']:.2f}",
        fontsize=10,
    )
    ax.set_xticks(h, [f"1/{round(1 / x)}" for x in h])
    ax.minorticks_off()
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out)
    print(f"wrote {args.out}; orders per level (w): {np.round(df['order_w'].to_numpy(), 3)}")


if __name__ == "__main__":
    main()
