"""``facecast mu``: train and score paper 002's system on GRID s1 (see :mod:`training.motion_units`)."""

from __future__ import annotations

import io
import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from assets.files import atomic_write_bytes
from realtime_core import VISUAL_PARAMS
from realtime_core.avmodel import AvModel
from realtime_core.mapping import MlpMapper, MlpSpeechModel, encode_mlp_model
from realtime_core.motion_units import MotionUnits, fit_motion_units
from training.errors import ConfigError
from training.mapper import MapperRecipe, fit_bank, fit_readout
from training.motion_units import (
    Say,
    displacement_scale,
    hmm_estimates,
    load_clips,
    lower_face_indices,
    mlp_estimates,
    mu_landmark_indices,
    of_split,
    score_mups,
    variance_report,
    with_features,
)

GRID_CREDIT = "GRID audio-visual corpus, talker s1: Cooke, Barker, Cunningham, Shao 2006 (CC BY 4.0)"


@dataclass(frozen=True, kw_only=True)
class MuTrainConfig:
    """See ``facecast mu --help``."""

    units: int | None = None
    variance: float = 0.97
    classes: tuple[int, ...] = (4, 8, 16, 32, 44)
    hidden: int = 20
    baseline_hidden: int = 600
    hmm_states: int = 16
    hmm_mix: int = 3
    hmm_iters: int = 20
    limit: int | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        if not 15 <= self.hidden <= 25:
            raise ConfigError(f"hidden must be 15..25 (the paper's range), got {self.hidden}")
        if not self.classes or min(self.classes) < 1:
            raise ConfigError(f"classes must be positive integers, got {self.classes}")


def _mups_of(clips, mu) -> tuple[np.ndarray, np.ndarray]:
    x = np.concatenate([c.features for c in clips])
    y = mu.project(np.concatenate([c.deform for c in clips]).astype(np.float64))
    return x, y


def train_and_score(root, out: Path, cfg: MuTrainConfig, *, cache_dir=None, say: Say = print) -> dict:
    from training.trainer import TrainRecipe, cmvn_statistics

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    skipped: list[str] = []
    clips = load_clips(root, cache_dir=cache_dir, limit=cfg.limit, skipped=skipped)
    train, val, test = (of_split(clips, s) for s in ("train", "val", "test"))
    say(
        f"{len(clips)} clips: {len(train)} train, {len(val)} val, {len(test)} test; {len(skipped)} refused by the "
        "extractor" + "".join(f"\n  {m}" for m in skipped)
    )
    if not (train and val and test):
        raise ConfigError("every split needs at least one clip (use more sentences)")
    # 1. Utterance MUs on the train split.
    d_train = np.concatenate([c.deform for c in train]).astype(np.float64)
    mu = fit_motion_units(d_train, n_units=cfg.units, min_variance=cfg.variance)
    var = variance_report(mu)
    say("variance explained: " + ", ".join(f"{r['units']}: {100 * r['explained']:.2f}%" for r in var[:10]))
    say(f"kept {mu.n_units} Utterance MUs ({100 * mu.explained()[mu.n_units - 1]:.2f}%)")
    # The same PCA on the whole lower face (103 landmarks: + jaw outline, outer cheeks) and on the lip
    # contours alone (40), for comparison with the MU landmark set.
    from training.facetrack import LIPS_INNER, LIPS_OUTER

    lower_train = np.concatenate([c.lower_face for c in train]).astype(np.float64)
    var_lower = variance_report(fit_motion_units(lower_train, n_units=1))
    pos = {v: i for i, v in enumerate(lower_face_indices())}
    cols = np.array([3 * pos[v] + j for v in sorted(set(LIPS_OUTER) | set(LIPS_INNER)) for j in range(3)])
    var_lips = variance_report(fit_motion_units(lower_train[:, cols], n_units=1))
    del lower_train
    say("whole lower face: " + ", ".join(f"{r['units']}: {100 * r['explained']:.2f}%" for r in var_lower[:10]))
    say("lips only: " + ", ".join(f"{r['units']}: {100 * r['explained']:.2f}%" for r in var_lips[:10]))
    # 2. Audio features: the live front end, CMVN statistics of the train split.
    recipe = TrainRecipe()
    fe = recipe.frontend
    mean, var_ = cmvn_statistics([c.samples for c in train], fe)
    clips = with_features(clips, fe, mean, var_)
    train, val, test = (of_split(clips, s) for s in ("train", "val", "test"))
    x_tr, y_tr = _mups_of(train, mu)
    readout = fit_readout(y_tr, np.concatenate([c.params for c in train]))
    scale = displacement_scale(train)
    centre = (fe.tc * fe.n_feat, (fe.tc + 1) * fe.n_feat)
    report: dict = {
        "credit": GRID_CREDIT,
        "config": asdict(cfg),
        "clips": {"train": len(train), "val": len(val), "test": len(test), "refused": skipped},
        "landmarks": len(mu_landmark_indices()),
        "units": mu.n_units,
        "variance": var,
        "variance_lower_face": var_lower,
        "variance_lips_only": var_lips,
        "train": {},
        "test": {},
        "val": {},
    }
    # Readout quality: true MUPs -> mouth parameters.
    rp = np.concatenate([c.params for c in test])
    rm = mu.project(np.concatenate([c.deform for c in test]).astype(np.float64))
    report["readout_r_test"] = dict(
        zip(VISUAL_PARAMS, map(float, np.diag(np.corrcoef(rp.T, (rm @ readout[0].T + readout[1]).T)[:4, 4:])))
    )
    # 3. The bank for each K, chosen on val.
    banks = {}
    for k in cfg.classes:
        t0 = time.perf_counter()
        bank = fit_bank(
            x_tr, y_tr, MapperRecipe(n_classes=k, hidden=cfg.hidden, seed=cfg.seed), class_slice=centre, readout=readout
        )
        m = MlpMapper(bank)
        s = score_mups(val, mlp_estimates(m, val), mu, scale, readout)
        banks[k] = bank
        report["val"][f"mlp_K{k}"] = s.as_json()
        say(f"K={k}: val R {s.r:.4f}, MSE {s.mse:.5f} ({time.perf_counter() - t0:.0f} s)")
    best_k = max(cfg.classes, key=lambda k: report["val"][f"mlp_K{k}"]["R"])
    report["chosen_classes"] = best_k
    systems: dict[str, MlpMapper | AvModel] = {"mlp": MlpMapper(banks[best_k])}
    model = MlpSpeechModel(
        bank=banks[best_k],
        frontend=fe,
        cmvn_mean=mean,
        cmvn_var=var_,
        visual_names=VISUAL_PARAMS,
        metadata={
            "paper": "Hong, Wen, Huang 2002, Sec. VI-A",
            "classes": best_k,
            "hidden": cfg.hidden,
            "units": mu.n_units,
            "credit": GRID_CREDIT,
            "val_R": report["val"][f"mlp_K{best_k}"]["R"],
        },
    )
    band, band_scores = choose_closure_band(model, root, cache_dir=cache_dir)
    model = replace(model, closure_band=band, metadata={**model.metadata, "closure_band_val": band_scores})
    report["closure_band"] = {"chosen": band, "val": band_scores}
    say(f"closure band {band} IOD (val)")
    atomic_write_bytes(out / "mlp_mapper.npz", encode_mlp_model(model))
    # 4. The single large MLP of the paper's argument.
    if cfg.baseline_hidden:
        t0 = time.perf_counter()
        base = fit_bank(
            x_tr,
            y_tr,
            MapperRecipe(n_classes=1, hidden=cfg.baseline_hidden, seed=cfg.seed, max_iter=100),
            class_slice=centre,
            readout=readout,
        )
        systems["single_mlp"] = MlpMapper(base)
        say(f"single MLP ({cfg.baseline_hidden} hidden) trained in {time.perf_counter() - t0:.0f} s")
    # 5. The HMM of paper 000 on the same UMUP targets.
    if cfg.hmm_states:
        from assets.modelfile import save_model
        from realtime_core.hmm import TrainConfig
        from training.corpus import Utterance
        from training.trainer import train_av_model

        utts = [
            Utterance(
                id=c.sentence_id,
                samples=c.samples,
                sample_rate_hz=c.sample_rate_hz,
                params=mu.project(c.deform.astype(np.float64)),
                phonemes=(),
                voice="s1",
                language="en",
                source="grid",
                speaker_group="s1",
            )
            for c in train
        ]
        hr = TrainRecipe(
            hmm=TrainConfig(n_states=cfg.hmm_states, n_mix=cfg.hmm_mix, n_iter=cfg.hmm_iters, tol=3e-4, seed=cfg.seed)
        )
        t0 = time.perf_counter()
        hmm, _ = train_av_model(
            utts,
            hr,
            visual_names=tuple(f"umup{i + 1}" for i in range(mu.n_units)),
            metadata={"credit": GRID_CREDIT, "targets": "GRID s1 Utterance MUPs"},
            on_iteration=lambda it, obj, _m: say(f"  HMM EM {it}: {obj:.3f}"),
        )
        say(f"HMM on UMUPs trained in {time.perf_counter() - t0:.0f} s")
        save_model(out / "hmm_mups.npz", hmm)
        systems["hmm"] = hmm
    # 6. Scores on train and test (every mapper's live-path estimates of the UMUPs).
    ests = {}
    for name, sysm in systems.items():
        ests[name] = {
            split: (mlp_estimates(sysm, cl) if isinstance(sysm, MlpMapper) else hmm_estimates(sysm, cl))
            for split, cl in (("train", train), ("test", test))
        }
        for split, cl in (("train", train), ("test", test)):
            report[split][name] = score_mups(cl, ests[name][split], mu, scale, readout).as_json()
        say(
            f"{name}: train R {report['train'][name]['R']:.4f}, test R {report['test'][name]['R']:.4f}, "
            f"test MSE {report['test'][name]['MSE']:.5f}"
        )
    # 7. Expressions (synthetic: the built-in head's ARKit recipes on the speaker's landmarks, see
    # training.mu_expressions), the Expression MUs, the second-stage mappers and the run-time checks.
    ests = {k: v for k, v in ests.items() if k in ("mlp", "hmm")}
    report["expressions"], stages = _expressions(clips, train, test, mu, scale, readout, ests, root, say)
    # The shipped mapper carries its second stages (Sec. VI-B) for expressions at run time.
    if stages.get("mlp"):
        from realtime_core.mapping import ExpressionMapper

        model = replace(
            model,
            expressions=ExpressionMapper(readout=readout[0], readout_bias=readout[1], stages=stages["mlp"]),
        )
        atomic_write_bytes(out / "mlp_mapper.npz", encode_mlp_model(model))
        say(f"mlp_mapper.npz: with second-stage mappers for {', '.join(stages['mlp'])}")
    report["test"]["true_mups"] = score_mups(
        test, [mu.project(c.deform.astype(np.float64)) for c in test], mu, scale, readout
    ).as_json()
    buf = io.BytesIO()
    np.savez(
        buf,
        mean=mu.mean,
        units=mu.units,
        eigenvalues=mu.eigenvalues,
        landmarks=np.array(mu_landmark_indices()),
        readout=readout[0],
        readout_bias=readout[1],
        scale=scale,
        format=np.array("facecast-motionunits"),
        version=np.array(1),
    )
    atomic_write_bytes(out / "motion_units.npz", buf.getvalue())
    _plot_variance(var, var_lower, var_lips, out / "variance.png", mu.n_units)
    atomic_write_bytes(out / "report.json", json.dumps(report, indent=1).encode())
    from training.mu_report import mu_markdown

    atomic_write_bytes(out / "report.md", mu_markdown(report, "facecast mu -o OUT").encode())
    return report


def refit_expression_stages(
    root, mapper_path: Path, out: Path, cfg: MuTrainConfig, *, cache_dir=None, say: Say = print
) -> dict:
    """Refit only the second stages (Sec. VI-B) of a mapper ``facecast mu`` trained, on the same data and
    settings, and write ``out/mlp_mapper.npz`` (the mapper with its new stages) and
    ``out/expressions.json`` (the ``expressions`` section of the report, the MLP mapper only).

    The speech bank is kept bit for bit; the Utterance MUs and the UMUP readout are refitted exactly as
    :func:`train_and_score` fits them and must equal the readout the file carries (else the file was not
    trained on these clips and settings: refused)."""
    from assets.modelfile import load_mlp_model
    from realtime_core.mapping import ExpressionMapper

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    model = load_mlp_model(mapper_path)
    clips = load_clips(root, cache_dir=cache_dir, limit=cfg.limit, skipped=[])
    train = of_split(clips, "train")
    mu = fit_motion_units(
        np.concatenate([c.deform for c in train]).astype(np.float64), n_units=cfg.units, min_variance=cfg.variance
    )
    clips = with_features(clips, model.frontend, model.cmvn_mean, model.cmvn_var)
    train, test = of_split(clips, "train"), of_split(clips, "test")
    _, y_tr = _mups_of(train, mu)
    readout = fit_readout(y_tr, np.concatenate([c.params for c in train]))
    if model.expressions is not None and not (
        model.expressions.readout.shape == readout[0].shape
        and np.allclose(model.expressions.readout, readout[0], atol=1e-6)
        and np.allclose(model.expressions.readout_bias, readout[1], atol=1e-6)
    ):
        raise ConfigError(f"{mapper_path}: its UMUP readout differs from the one refitted on these clips and settings")
    scale = displacement_scale(train)
    m = MlpMapper(model.bank)
    ests = {"mlp": {"train": mlp_estimates(m, train), "test": mlp_estimates(m, test)}}
    report, stages = _expressions(clips, train, test, mu, scale, readout, ests, root, say)
    model = replace(
        model, expressions=ExpressionMapper(readout=readout[0], readout_bias=readout[1], stages=stages["mlp"])
    )
    atomic_write_bytes(out / "mlp_mapper.npz", encode_mlp_model(model))
    atomic_write_bytes(out / "expressions.json", json.dumps(report, indent=1).encode())
    say(f"{out / 'mlp_mapper.npz'}: second stages for {', '.join(stages['mlp'])} refitted; bank unchanged")
    return report


BANDS = (0.0, 0.01, 0.02, 0.03, 0.04, 0.05)


def choose_closure_band(model: MlpSpeechModel, root, *, cache_dir=None) -> tuple[float, dict]:
    """The output stage's closure band for the MLP mapper, chosen on the val split as the HMM's is
    (scored by :func:`training.reallips.evaluate_lips`): among the bands that do not lower r(mouth_open)
    below its value without a band, the one whose closure rate is closest to the truth's."""
    from training.reallips import evaluate_lips, s1_clips

    clips = s1_clips("val", root=root, cache_dir=cache_dir)
    scores = {}
    for band in BANDS:
        s, _ = evaluate_lips(replace(model, closure_band=band), clips)
        scores[str(band)] = {
            "r_mouth_open": s.r["mouth_open"],
            "closure_rate": s.closure_rate,
            "truth_closure_rate": s.truth_closure_rate,
        }
    r0 = scores["0.0"]["r_mouth_open"]
    ok = [b for b in BANDS if scores[str(b)]["r_mouth_open"] >= r0 - 1e-9] or [0.0]
    best = min(ok, key=lambda b: abs(scores[str(b)]["closure_rate"] - scores[str(b)]["truth_closure_rate"]))
    return best, scores


def _expressions(clips, train, test, mu, scale, readout, ests, root, say: Say) -> tuple[dict, dict]:
    from assets.errors import LandmarkError
    from assets.grid import read_words, sentences
    from assets.heads.builtin import load_builtin_head
    from assets.heads.landmarks import read_landmarks
    from realtime_core.expressions import EXPRESSIONS
    from realtime_core.mapping import ExpressionMapper
    from realtime_core.mapping.expression import express
    from training.motion_units import score
    from training.mu_expressions import (
        closure_rate,
        closure_windows,
        emu_readout,
        expression_deformations,
        expression_stage,
        expressive,
        fit_second_stage,
        fit_units,
        reconstruct,
        second_stage_predict,
        under_expression,
    )

    head = load_builtin_head()
    mp_path = Path(__file__).resolve().parents[1] / "assets" / "heads" / "landmarks" / "mediapipe_canonical.json"
    mp: dict[str, int] = {}
    for k, v in read_landmarks(mp_path).items():
        if not isinstance(v, int):  # this file names MediaPipe vertex indices, not [x, y, z] points
            raise LandmarkError(f"{mp_path}: landmark {k!r} must be a vertex index, got {v!r}")
        mp[k] = v
    neutral = np.mean([c.neutral for c in train], axis=0)
    deltas = expression_deformations(neutral, mu_landmark_indices(), head, mp)
    # Keyframe sets and the eq. 4 round trip MUPs -> keyframes -> MUPs on the test frames.
    from realtime_core.blendshapes import ARKIT_NAMES
    from realtime_core.motion_units import in_mu_space, round_trip_error
    from training.mu_expressions import carried, head_correspondence
    from training.mu_keyframes import keyframe_sets

    verts, sim = head_correspondence(neutral, mu_landmark_indices(), head, mp)
    arkit = {n: carried(head, verts, sim, {n: 1.0}) for n in ARKIT_NAMES}
    align = {s.sentence_id: s.align for s in sentences(root)}
    words_of = {c.sentence_id: read_words(align[c.sentence_id]) for c in clips}
    c_test = mu.project(np.concatenate([c.deform for c in test]).astype(np.float64))
    from training.grid_phones import read_grid_phones_file

    phones_of = {
        sid: [(p.phoneme, p.start_s, p.end_s) for p in sp.phones] for sid, sp in read_grid_phones_file().items()
    }
    round_trip = {}
    for name, keys in keyframe_sets(train, words_of, deltas, arkit, phones_of).items():
        row: dict = {"keyframes": len(keys.names), "names": list(keys.names)}
        # eq. 4 as printed (landmark space) and in the MU subspace, each unconstrained and with b >= 0,
        # on the held-out test frames of real speech.
        for space, ks in (("landmarks", keys), ("mu", in_mu_space(keys, mu))):
            for label, nonneg in (("ls", False), ("nonneg", True)):
                err = round_trip_error(ks, mu, c_test, nonnegative=nonneg)
                row[f"{space}_{label}"] = {
                    "max_error_of_range": float(err.max()),
                    "mean_error_of_range": float(err.mean()),
                    "per_mu": err.tolist(),
                }
        round_trip[name] = row
        say(
            f"keyframes {name} ({len(keys.names)}): round trip max error % of the MUP range: "
            + ", ".join(f"{k} {100 * v['max_error_of_range']:.2f}" for k, v in row.items() if isinstance(v, dict))
        )
    out: dict = {
        "source": "synthetic: built-in head ARKit recipes carried onto the speaker's landmarks",
        "keyframe_round_trip": round_trip,
        "delta_rms_iod": {e: float(np.sqrt(np.mean(deltas[e] ** 2))) for e in EXPRESSIONS},
    }
    stages: dict[str, dict] = {name: {} for name in ests}
    for e in EXPRESSIONS:
        tr_k, te_k = expressive(train, deltas[e]), expressive(test, deltas[e])
        ex = fit_units(mu, tr_k, e)
        # Residual energy (eq. 1) the expression's mean m_k0 and its 2 units rebuild, on the train frames
        # (the paper: >= 98.13 %); and the PCA spectrum of the residuals around that mean.
        r = mu.residual(np.concatenate([c.deform for c in tr_k]).astype(np.float64))
        rec = ex.basis.reconstruct(ex.basis.project(r))
        out[e] = {
            "emu_residual_energy_explained": float(1 - ((r - rec) ** 2).sum() / (r**2).sum()),
            "emu_residual_explained_2": float(ex.basis.explained()[1]),
            "train": {},
            "test": {},
        }
        # The EMUs' effect on the four parameters as measured at the speaker's rest face (see emu_readout).
        emu = emu_readout(neutral, mu_landmark_indices(), ex, ex.basis.project(r))
        for name, est in ests.items():
            weights = fit_second_stage(
                np.concatenate(est["train"]), mu, ex, np.concatenate([c.deform for c in tr_k]).astype(np.float64)
            )
            stage = expression_stage(e, weights, mu, ex, emu=emu)
            stages[name][e] = stage
            for split, cl, e_list in (("train", tr_k, est["train"]), ("test", te_k, est["test"])):
                c_in = np.concatenate(e_list)
                d_hat = reconstruct(mu, ex, second_stage_predict(weights, c_in))
                td = np.concatenate([c.deform for c in cl]).astype(np.float64)
                tp = np.concatenate([c.params for c in cl])
                # The mouth parameters of the expressive estimate as at run time: speech readout + the
                # stage's change (realtime_core.mapping.expression); r against the sentence's own parameters.
                mapper = ExpressionMapper(readout=readout[0], readout_bias=readout[1], stages={e: stage})
                p_hat = c_in @ readout[0].T + readout[1] + mapper.stage_delta(e, c_in)
                out[e][split][name] = score(td, d_hat, scale, tp, p_hat).as_json()
        say(f"{e}: test R " + ", ".join(f"{n} {out[e]['test'][n]['R']:.3f}" for n in ests))
    # Run time: bilabial closures and rounding under a full smile, on the test sentences.
    windows = [closure_windows(read_words(align[c.sentence_id])) for c in test]
    truth = [c.params for c in test]
    theta = 0.03
    checks: dict = {"threshold_iod": theta, "truth_closure_rate": closure_rate(truth, windows, theta)}
    tp = np.concatenate(truth)
    smile = np.zeros(len(EXPRESSIONS))
    smile[EXPRESSIONS.index("smile")] = 1.0
    for name, est in ests.items():
        neutral_p = [m @ readout[0].T + readout[1] for m in est["test"]]
        mapper = ExpressionMapper(readout=readout[0], readout_bias=readout[1], stages=stages[name])
        staged = [
            express(p, np.tile(smile, (len(p), 1)), mups=m, mapper=mapper) for p, m in zip(neutral_p, est["test"])
        ]
        row = {}
        for label, tracks in (
            ("neutral", neutral_p),
            ("smile_fixed", under_expression(neutral_p, "smile", 1.0)),
            ("smile", staged),
        ):
            ep = np.concatenate(tracks)
            row[label] = {
                "closure_rate": closure_rate(tracks, windows, theta),
                "r_mouth_open": float(np.corrcoef(tp[:, 2], ep[:, 2])[0, 1]),
                "r_lip_stretch": float(np.corrcoef(tp[:, 1], ep[:, 1])[0, 1]),
            }
        checks[name] = row
        say(
            f"{name}: closure rate {row['neutral']['closure_rate']:.3f} -> {row['smile']['closure_rate']:.3f} "
            f"under smile (second stage; fixed offsets {row['smile_fixed']['closure_rate']:.3f}); r(mouth_open) "
            f"{row['neutral']['r_mouth_open']:.3f} -> {row['smile']['r_mouth_open']:.3f} "
            f"(fixed {row['smile_fixed']['r_mouth_open']:.3f})"
        )
    out["smile_checks"] = checks
    return out, stages


def _plot_variance(var: list[dict], var_lower: list[dict], var_lips: list[dict], png: Path, kept: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    k = [r["units"] for r in var]
    e = [100 * r["explained"] for r in var]
    fig, ax = plt.subplots(figsize=(6, 3.5), dpi=120)
    ax.plot(k, e, "o-", label=f"MU landmarks (lips, chin, perioral cheeks: {len(mu_landmark_indices())})")
    ax.plot(
        [r["units"] for r in var_lower],
        [100 * r["explained"] for r in var_lower],
        "^:",
        ms=3,
        label="whole lower face (+ jaw outline, outer cheeks: 103)",
    )
    ax.plot(
        [r["units"] for r in var_lips],
        [100 * r["explained"] for r in var_lips],
        "s--",
        ms=3,
        label="lip contours only (40)",
    )
    ax.axhline(97, color="grey", ls="--", lw=1, label="97 %")
    ax.axvline(kept, color="C1", ls=":", lw=1, label=f"kept: {kept}")
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("Utterance MUs")
    ax.set_ylabel("variance explained (%)")
    ax.set_title("GRID s1 lower-face deformation: PCA (train split)")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png)
    plt.close(fig)


def load_motion_units(path: Path) -> tuple[MotionUnits, tuple[np.ndarray, np.ndarray], np.ndarray, tuple[int, ...]]:
    """``motion_units.npz`` -> (MUs, readout (matrix, bias), displacement scale, landmark indices); a file
    of another kind or version is refused naming the file."""
    from assets.errors import FileProblem

    try:
        with np.load(path, allow_pickle=False) as z:
            a = {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise FileProblem(path, f"cannot be read as a motion-units file ({exc})") from None
    if str(a.get("format")) != "facecast-motionunits" or int(a.get("version", -1)) != 1:
        raise FileProblem(
            path, f"not a facecast-motionunits v1 file (format {a.get('format')!s}, version {a.get('version')!s})"
        )
    mu = MotionUnits(mean=a["mean"], units=a["units"], eigenvalues=a["eigenvalues"])
    return mu, (a["readout"], a["readout_bias"]), a["scale"], tuple(int(i) for i in a["landmarks"])


def score_saved(out: Path, root=None, *, cache_dir=None, say: Say = print) -> dict:
    """Re-score the models ``facecast mu`` wrote to ``out`` on the train and test sentences (``facecast eval
    --mu OUT``); the expression, variance and keyframe numbers come from ``out/report.json``."""
    from assets.modelfile import load_mlp_model, load_model

    out = Path(out)
    mu, readout, scale, idx = load_motion_units(out / "motion_units.npz")
    if idx != mu_landmark_indices():
        raise ConfigError(f"{out / 'motion_units.npz'}: landmark set differs from this version's MU_LANDMARKS")
    mlp = load_mlp_model(out / "mlp_mapper.npz")
    report = json.loads((out / "report.json").read_text())
    # The sentences the run used: a `facecast mu --limit N` run was re-scored on all 900 (measuring every
    # uncached clip's face first, ~1.3 s each) and reported beside test numbers of other sentences.
    limit = report.get("config", {}).get("limit")
    clips = load_clips(root, cache_dir=cache_dir, limit=limit, skipped=[])
    clips = with_features(clips, mlp.frontend, mlp.cmvn_mean, mlp.cmvn_var)
    train, test = of_split(clips, "train"), of_split(clips, "test")
    systems: dict[str, MlpMapper | AvModel] = {"mlp": mlp.mapper()}
    if (out / "hmm_mups.npz").is_file():
        systems["hmm"] = load_model(out / "hmm_mups.npz")
    for name, sysm in systems.items():
        for split, cl in (("train", train), ("test", test)):
            est = mlp_estimates(sysm, cl) if isinstance(sysm, MlpMapper) else hmm_estimates(sysm, cl)
            report[split][name] = score_mups(cl, est, mu, scale, readout).as_json()
        say(f"{name}: train R {report['train'][name]['R']:.4f}, test R {report['test'][name]['R']:.4f}")
    return report
