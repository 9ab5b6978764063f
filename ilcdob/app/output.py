"""Report writer of ``ilcdob reproduce``: results.json, figures and a Markdown index.

Everything is written atomically; ``results.json`` is written last, so its presence means
the figures beside it are complete.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ilcdob.atomic import write_json_atomic, write_text_atomic
from ilcdob.design.laws import LAW_DESCRIPTIONS
from ilcdob.validation.figures import write_figures
from ilcdob.validation.reproduce import ReproductionResult

__all__ = ["write_reproduction", "markdown_index"]

_FIGURE_TEXT = {
    "rmse_bars.png": "Tracking RMSE per scenario and system (log scale): no DOB, only DOB, learning iterations.",
    "bode_loops.png": "Bode plots of G_r and G_d of every system (dotted: G_d without DOB).",
    "identified_models.png": "Identified plant models with their 3-sigma multiplicative uncertainty band "
                             "(from the parameter covariance of the fit).",
    "bode_learning.png": "Bode plots of the learning filters L1 and L2 of every pair flown (with equal "
                         "Q filters L2 = (1 - Q_j)/(1 - Q_{j-1}) = 1 exactly).",
    "bode_te.png": "Te1, Te2 (error propagation with learning when every true plant is 10 % stronger "
                   "than its model; with exact models both vanish) and Omega (disturbance -> DOB estimate).",
}


def markdown_index(res: ReproductionResult, figures: list[str]) -> str:
    """A README.md for the output folder: the RMSE table and every figure."""
    plant_lines = getattr(res, "markdown_plant", None)  # nonlinear plant: its own description
    lines = [
        "# Reproduction of Modi et al. (2024), Section IV",
        "",
        *(plant_lines() if plant_lines else [
            f"Fleet: `{Path(res.fleet.source).name}` ({', '.join(res.fleet.names)}), sample time "
            f"{res.fleet.sample_time} s, exact models (Case I of the Theorem: each simulated plant is its "
            f"model), {res.iterations} learning "
            "iterations. Regenerate with `ilcdob reproduce"
            + ("" if res.law == "paper" else f" --law {res.law}")
            + " --out <dir>`; numbers are in `results.json`."]),
        "",
        f"Learning law: **{res.law}**, {LAW_DESCRIPTIONS[res.law]} (`ilcdob.design.laws`; choose with `--law`).",
        "",
        "Tracking RMSE in mm (no DOB / only DOB / learning 1..n) and RMSE of the total disturbance "
        "estimate d_hat + d_f against the true disturbance in m/s^2 (only DOB / learning 1):",
        "",
        "| scenario | system | no DOB | only DOB | " + " | ".join(
            f"learning {i + 1}" for i in range(res.iterations)) + " | learning 1 / DOB | d est. DOB | d est. learning 1 |",
        "|---|---|---|---|" + "---|" * res.iterations + "---|---|---|",
    ]
    for sr in res.scenarios:
        for name in sr.order:
            m = sr.systems[name].metrics()
            learn = " | ".join(f"{1e3 * v:.3f}" for v in m["rmse_learning"])
            lines.append(
                f"| {sr.scenario.id} | {name} | {1e3 * m['rmse_no_dob']:.1f} | {1e3 * m['rmse_dob']:.1f} | "
                f"{learn} | {m['rmse_learning'][0] / m['rmse_dob']:.4f} | {m['rmse_dhat_dob']:.3f} | "
                f"{m['rmse_dhat_learning'][0]:.3f} |")
    idents = [(s.name, s.identification, s.nominal_plant) for s in res.fleet.systems if s.identification]
    if idents:
        lines += ["", "## Identified plant models", "",
                  "Identified from synthetic step and chirp flights of the nonlinear vehicles "
                  "(`ilcdob identify-fleet`); fit in % (MATLAB definition) on estimation and held-out flights, "
                  "1-sigma parameter uncertainty from the fit's covariance.", "",
                  "| system | model P(s) | parameters (1 sigma) | fit estimation | fit validation |",
                  "|---|---|---|---|---|"]
        for name, ident, plant in idents:
            sd = np.sqrt(np.diag(np.asarray(ident.covariance)))
            pars = ", ".join(f"{v:.4g} +- {e:.2g}" for v, e in zip(ident.parameters, sd))
            model = f"({' '.join(f'{v:.4g}' for v in plant.num)}) / ({' '.join(f'{v:.4g}' for v in plant.den)})"
            lines.append(f"| {name} | {model} | {pars} | {ident.fit_estimation:.2f} % | {ident.fit_validation:.2f} % |")
    lines += ["", f"Run time {res.elapsed_s:.1f} s for the simulations.", "", "## Figures", ""]
    for fig in figures:
        text = _FIGURE_TEXT.get(fig)
        if text is None and fig.startswith("error_s"):
            text = f"Scenario {fig[7:-4]}: tracking error against time."
        elif text is None and fig.startswith("disturbance_s"):
            text = f"Scenario {fig[13:-4]}: disturbance estimates against the true disturbance."
        lines += [f"{text}", "", f"![{fig}]({fig})", ""]
    return "\n".join(lines)


def write_reproduction(res: ReproductionResult, out: str | Path, figures: bool = True) -> Path:
    """Write figures (optional), ``README.md`` and ``results.json`` into ``out``.

    Returns the path of ``results.json``.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = [p.name for p in write_figures(res, out)] if figures else []
    write_text_atomic(out / "README.md", markdown_index(res, names))
    path = out / "results.json"
    write_json_atomic(path, res.to_dict())
    return path
