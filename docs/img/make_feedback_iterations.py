"""The plot of docs/feedback.md: mean keypoint error against the number of updates.

Run: ``python docs/img/make_feedback_iterations.py RENDERER.json LEARNED.json`` (writes
``docs/img/feedback_iterations.png``), where each JSON is the output of
``python -m handsim.estimators.feedback.evaluate --bench bench --iterations 3 --out X.json``
for one updater (the shipped one with the renderer synthesizer; the recipe's learned-synthesizer
updater with ``--synthesizer learned``), as in docs/feedback.md.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

OUT = Path(__file__).parent / "feedback_iterations.png"
SETS = ("hand_third_person", "hand_object", "hand_egocentric")


def main() -> None:
    """Plot the two JSONs into OUT."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("renderer", type=Path, help="evaluate JSON of the renderer's updater")
    parser.add_argument("learned", type=Path, help="evaluate JSON of the learned one's updater")
    args = parser.parse_args()
    fig, ax = plt.subplots(figsize=(6.0, 3.6), dpi=120)
    for path, style, label in ((args.renderer, "-o", "renderer"), (args.learned, "--s", "learned")):
        sets = json.loads(path.read_text())["sets"]
        for color, name in zip(("C0", "C1", "C2"), SETS, strict=True):
            errors_mm = sets[name]["mean_error_mm"]
            ax.plot(range(len(errors_mm)), errors_mm, style, color=color, label=f"{name}, {label}")
    ax.set_xlabel("updates (0: DeepPrior++ alone)")
    ax.set_ylabel("mean keypoint error (mm)")
    ax.set_xticks(range(4))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("handsim-bench-v1: the feedback loop's updates", fontsize=9)
    fig.tight_layout()
    fig.savefig(OUT)
    print(f"written: {OUT}")


if __name__ == "__main__":
    main()
