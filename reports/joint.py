"""What a joint identification's report (one model of several recordings, identify.joint) shows beside a
single recording's: the recordings' table (samples, band, rows fitted and held out) and, under the pooled
validation, the joint model's held-out fit in each recording next to the recording's own model
(reports.identification draws the rest, the same for one recording or several)."""
from __future__ import annotations

from .html import Page
from .text import fit_text


def joint_data_section(page: Page, result: dict, names: list[str]) -> None:
    """One row per recording: samples and rate, the chain's band, the rows fitted and held out."""
    chain = result.get("chain") or {}
    rows = []
    for name, p in zip(names, result["recordings"]):
        v0, v1 = p["valid_samples"]
        rows.append([name, f"{p['samples']} at {p['fs_hz']:g} Hz ({p['samples'] / p['fs_hz']:.1f} s)",
                     f"{p['band_hz'][0]:.3g}-{p['band_hz'][1]:.3g} Hz", f"{v1 - v0}",
                     f"{p['fit_samples']} / {p['heldout_samples']}"])
    page.heading("Data")
    page.table(["recording", "samples", "integration band", "samples used", "fitted on / held out"], rows,
               f"The recordings fitted as one model (joint identification: each through its own measurement "
               f"chain and band, held-out blocks per recording, {chain.get('holdout', 'held out')}; the normal "
               "equations summed). Held-out samples are never used for fitting; the validation below is on them.")


def joint_validation_table(page: Page, result: dict, names: list[str]) -> None:
    """The joint model's held-out free-run fit in each recording, and how it compares with that recording's
    own model (NRMSE ratio joint / alone: far above 1, the rig behaved differently in that recording)."""
    rows, said = [], []
    for name, p in zip(names, result["recordings"]):
        v = p.get("validation")
        fits = [fit_text(v["heldout"][k]) if v else "-" for k in ("q1_dot", "q1", "q2")]
        ratio = p.get("nrmse_ratio_joint_to_alone") or {}
        ratios = ["-" if ratio.get(k) is None else f"{ratio[k]:.2f}" for k in ("displacement", "velocity")]
        rows.append([name, *fits, *ratios, p["status"]])
        if p.get("reason") and p["status"] != "ok":
            said.append(f"{name}: {p['status']}: {p['reason']}")
    rule = (result.get("joint") or {}).get("change_rule") or {}
    page.table(["recording", "fit, acceleration", "fit, velocity", "fit, displacement", "NRMSE joint / alone, disp.",
                "NRMSE joint / alone, vel.", "status"], rows,
               "The joint model's free run on each recording's held-out samples, and its NRMSE there over that of a "
               "model fitted to the recording alone" + (f" (above {rule['change_ratio']:g} while the recording's "
                                                       f"own coefficients lie more than {rule['z_change']:g} standard "
                                                       "errors off the joint ones, the recording is inconsistent: the "
                                                       "rig behaved differently there)" if rule else "") + ".")
    for line in said:
        page.paragraph(line)
