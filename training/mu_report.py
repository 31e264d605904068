"""Markdown of paper 002's numbers (``facecast mu`` / ``facecast eval --mu``), from a report dict."""

from __future__ import annotations

SYSTEMS = (
    ("mlp", "MLP bank (GMM-selected, chosen K)"),
    ("single_mlp", "single large MLP"),
    ("hmm", "HMM (paper 000) on the same UMUPs"),
    ("true_mups", "true UMUPs (MU reconstruction ceiling)"),
)


def _row(name: str, s: dict) -> str:
    r = s["r_mouth_params"]
    return (
        f"| {name} | {s['R']:.3f} | {s['nu_d']:.3f} | {s['nu_d_est']:.3f} | {s['MSE']:.4f} | "
        f"{r['upper_lip_raise']:.2f} / {r['lip_stretch']:.2f} / {r['mouth_open']:.2f} / {r['lip_corner_depress']:.2f} |"
    )


def mu_markdown(rep: dict, command: str) -> str:
    out = [
        (
            f"Command: `{command}`. {rep.get('credit', '')}. Sentences: train {rep['clips']['train']}, "
            f"val {rep['clips']['val']}, test {rep['clips']['test']} (`assets.grid.split_of`; "
            f"{len(rep['clips'].get('refused', []))} refused by the extractor); K chosen on val, "
            "numbers on train and test. R, nu, MSE: paper 002 eq. 6-8 on the lower-face landmark displacements "
            "rebuilt from the estimated UMUPs, each coordinate divided by its maximum absolute displacement over "
            "the training data; r: Pearson r of the four mouth parameters read out of the UMUPs."
        ),
        "",
    ]
    v = {r["units"]: r["explained"] for r in rep["variance"]}
    vl = {r["units"]: r["explained"] for r in rep.get("variance_lips_only", [])}
    out += [
        "**Utterance MUs** (PCA of the train split; cumulative variance explained):",
        "",
        "| MUs | " + " | ".join(str(k) for k in range(1, 11)) + " |",
        "|---" * 11 + "|",
        "| lower face (103 landmarks) | " + " | ".join(f"{100 * v[k]:.2f}" for k in range(1, 11) if k in v) + " |",
    ]
    if vl:
        out.append(
            "| lip contours only (40) | " + " | ".join(f"{100 * vl[k]:.2f}" for k in range(1, 11) if k in vl) + " |"
        )
    out += ["", f"Kept: {rep['units']} Utterance MUs (the fewest reaching 97 % on the lower face).", ""]
    if rep.get("val"):
        out += [
            "**K on the val split** (R of the MLP bank):",
            "",
            "| K | " + " | ".join(k.split("K")[1] for k in rep["val"]) + " |",
            "|---" * (len(rep["val"]) + 1) + "|",
            "| val R | " + " | ".join(f"{s['R']:.4f}" for s in rep["val"].values()) + " |",
            "",
            f"Chosen: K = {rep['chosen_classes']}.",
            "",
        ]
    for split in ("train", "test"):
        out += [
            f"**{split.capitalize()} set, neutral** (paper Table {'I' if split == 'train' else 'II'}):",
            "",
            "| system | R | nu_d | nu_d' | MSE | r: raise / stretch / open / corners |",
            "|---|---|---|---|---|---|",
        ]
        for key, label in SYSTEMS:
            if key in rep[split]:
                out.append(_row(label, rep[split][key]))
        out.append("")
    ex = rep.get("expressions")
    if ex:
        names = [e for e in ("smile", "sad", "surprise", "anger") if e in ex]
        out += [
            (
                "**Expressions** (synthetic: the built-in head's ARKit recipes carried onto the speaker's "
                "landmarks and added to the real sentences; second-stage MLP per expression, 30 hidden units). "
                "A constant added deformation leaves R unchanged by construction; MSE shows the offset error."
            ),
            "",
            (
                "| expression | residual energy rebuilt by m_k0 + 2 EMUs | mapper "
                "| train R | train MSE | test R | test MSE |"
            ),
            "|---|---|---|---|---|---|---|",
        ]
        for e in names:
            for m in ex[e]["test"]:
                tr, te = ex[e]["train"][m], ex[e]["test"][m]
                out.append(
                    f"| {e} | {100 * ex[e]['emu_residual_energy_explained']:.1f} % | {m} | {tr['R']:.3f} | "
                    f"{tr['MSE']:.4f} | {te['R']:.3f} | {te['MSE']:.4f} |"
                )
        sc = ex["smile_checks"]
        out += [
            "",
            (
                f"**Speech under a full smile** (test sentences, run-time composition; closure: the smallest "
                f"mouth_open within -60..+120 ms of a /b p/-initial word's start <= {sc['threshold_iod']} IOD; "
                f"truth closure rate {sc['truth_closure_rate']:.3f}):"
            ),
            "",
            (
                "| mapper | closure rate neutral | under smile | change (points) | r(mouth_open) neutral | under smile "
                "| r(lip_stretch) neutral | under smile |"
            ),
            "|---|---|---|---|---|---|---|---|",
        ]
        for m in ("mlp", "hmm"):
            if m in sc:
                n, s = sc[m]["neutral"], sc[m]["smile"]
                out.append(
                    f"| {m} | {n['closure_rate']:.3f} | {s['closure_rate']:.3f} | "
                    f"{100 * (s['closure_rate'] - n['closure_rate']):+.1f} | {n['r_mouth_open']:.3f} | "
                    f"{s['r_mouth_open']:.3f} | {n['r_lip_stretch']:.3f} | {s['r_lip_stretch']:.3f} |"
                )
        rt = ex.get("keyframe_round_trip")
        if rt:
            out += [
                "",
                (
                    "**Keyframe round trip** MUPs -> keyframes -> MUPs (eq. 4, test frames; RMS error per MU / "
                    "that MU's range):"
                ),
                "",
                "| keyframe set | keyframes | max over MUs | mean | per MU (%) |",
                "|---|---|---|---|---|",
            ]
            for k, r in rt.items():
                out.append(
                    f"| {k} | {r['keyframes']} | {100 * r['max_error_of_range']:.1f} % | "
                    f"{100 * r['mean_error_of_range']:.1f} % | "
                    + " ".join(f"{100 * x:.1f}" for x in r["per_mu"])
                    + " |"
                )
    return "\n".join(out) + "\n"
