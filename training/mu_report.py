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
            "numbers on train and test. R, nu, MSE: paper 002 eq. 6-8 on the MU landmarks' displacements "
            "rebuilt from the estimated UMUPs, each coordinate divided by its maximum absolute displacement over "
            "the training data; r: Pearson r of the four mouth parameters read out of the UMUPs."
        ),
        "",
    ]
    v = {r["units"]: r["explained"] for r in rep["variance"]}
    rows = (
        (f"MU landmarks: lips, chin, perioral cheeks ({rep.get('landmarks', '?')})", v),
        (
            "whole lower face (+ jaw outline, outer cheeks: 103)",
            {r["units"]: r["explained"] for r in rep.get("variance_lower_face", [])},
        ),
        ("lip contours only (40)", {r["units"]: r["explained"] for r in rep.get("variance_lips_only", [])}),
    )
    out += [
        "**Utterance MUs** (PCA of the train split; cumulative variance explained, %):",
        "",
        "| MUs | " + " | ".join(str(k) for k in range(1, 11)) + " |",
        "|---" * 11 + "|",
    ]
    for label, vals in rows:
        if vals:
            out.append(f"| {label} | " + " | ".join(f"{100 * vals[k]:.2f}" for k in range(1, 11) if k in vals) + " |")
    out += ["", f"Kept: {rep['units']} Utterance MUs (the fewest reaching 97 % on the MU landmarks).", ""]
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
        # The paper's Tables I and II side by side: neutral and each expression, per mapper and split.
        out += [
            "",
            "**Side by side** (paper 002 Tables I and II: neutral and each expression, HMM and MLP mapper):",
            "",
            "| split | mapper | metric | neutral | " + " | ".join(names) + " |",
            "|---" * (4 + len(names)) + "|",
        ]
        for split in ("train", "test"):
            for m in ("hmm", "mlp"):
                if m not in rep[split] or any(m not in ex[e][split] for e in names):
                    continue
                cols = [rep[split][m]] + [ex[e][split][m] for e in names]
                for key, label in (("R", "R"), ("nu_d", "nu_d"), ("nu_d_est", "nu_d'"), ("MSE", "MSE")):
                    fmt = "{:.4f}" if key == "MSE" else "{:.3f}"
                    out.append(f"| {split} | {m} | {label} | " + " | ".join(fmt.format(c[key]) for c in cols) + " |")
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
            for key, how in (("smile", "second-stage MLP"), ("smile_fixed", "fixed offsets")):
                if m in sc and key in sc[m]:
                    n, s = sc[m]["neutral"], sc[m][key]
                    out.append(
                        f"| {m}, {how} | {n['closure_rate']:.3f} | {s['closure_rate']:.3f} | "
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
                "| keyframe set | keyframes | solved in | weights | max over MUs | mean | per MU (%) |",
                "|---|---|---|---|---|---|---|",
            ]
            spaces = (
                ("landmarks", "landmark space (eq. 4 as printed)"),
                ("mu", "MU subspace"),
            )
            for k, r in rt.items():
                for space, where in spaces:
                    for label, how in (("ls", "least squares"), ("nonneg", "b >= 0")):
                        e = r.get(f"{space}_{label}")
                        if e is None:
                            continue
                        out.append(
                            f"| {k} | {r['keyframes']} | {where} | {how} | {100 * e['max_error_of_range']:.1f} % | "
                            f"{100 * e['mean_error_of_range']:.1f} % | "
                            + " ".join(f"{100 * x:.1f}" for x in e["per_mu"])
                            + " |"
                        )
    return "\n".join(out) + "\n"
