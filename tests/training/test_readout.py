"""Fitting the readout: a linear readout fitted on data made by a known causal linear filter recovers it;
the fitted MLP readout's live path equals the fit's own estimates; per-parameter loss weights."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from realtime_core import VISUAL_PARAMS
from tests.realtime_core.test_readout import DA, DV, M, N, small_model
from training.errors import ConfigError
from training.readout import ReadoutSpec, Traced, choose_band, choose_readout, estimates, fit_readout

# The MLPs here are cut to a few epochs to keep the tests fast; the properties tested (the live path equals
# the scoring, an ensemble is its members' mean) hold for any weights, so sklearn's "not converged" is noise.
FEW_EPOCHS = pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")


def _traced(rng: np.random.Generator, n_clips: int, make_truth) -> list[Traced]:
    out = []
    for i in range(n_clips):
        T = 60
        raw = np.cumsum(rng.standard_normal((T, DV)) * 0.1, axis=0)
        post = rng.dirichlet(np.ones(N * M), T)
        audio = rng.standard_normal((T, DA))
        out.append(Traced(f"c{i}", make_truth(raw, post, audio), raw, post, audio, np.zeros(T), []))
    return out


def test_a_linear_readout_recovers_a_known_causal_filter():
    """truth_t = B0 x_t + B1 x_{t-1} + B2 x_{t-2} + C a_t + D p_t + c (state posteriors): ridge with a
    tiny penalty on noise-free data gives back B, C, D and c."""
    rng = np.random.default_rng(0)
    B = rng.standard_normal((3, DV, DV))
    C = rng.standard_normal((DA, DV)) * 0.2
    D = rng.standard_normal((N, DV))
    c = rng.standard_normal(DV)

    def truth(raw, post, audio):
        pad = np.concatenate([raw[:1], raw[:1], raw])  # frames before the first repeat it
        state = post.reshape(len(post), N, M).sum(2)
        return sum(pad[2 - k : 2 - k + len(raw)] @ B[k] for k in range(3)) + audio @ C + state @ D + c

    train = _traced(rng, 30, truth)
    model = small_model(0)
    ro = fit_readout(model, train, ReadoutSpec(taps=3, audio=True, posteriors="state", hidden=0, alpha=1e-9))
    w = ro.w2
    np.testing.assert_allclose(w[: 3 * DV].reshape(3, DV, DV), B, atol=1e-5)
    np.testing.assert_allclose(w[3 * DV : 3 * DV + DA], C, atol=1e-5)
    # the state posteriors sum to 1, so D is identified only up to a constant shared with the bias
    d = w[3 * DV + DA :]
    np.testing.assert_allclose(d - d.mean(0), D - D.mean(0), atol=1e-5)
    np.testing.assert_allclose(ro.b2 + d.mean(0), c + D.mean(0), atol=1e-5)


@FEW_EPOCHS
def test_chosen_readout_is_what_the_live_path_runs():
    """choose_readout on synthetic clips: the returned model's inverter, fed audio rows, equals the
    estimates the choice was scored with (readout, then the output stage of the chosen band)."""
    rng = np.random.default_rng(1)
    model = small_model(2)
    oa_clips = [rng.standard_normal((50, DA)) for _ in range(12)]
    traced = []
    for i, oa in enumerate(oa_clips):
        raw, post, audio = model.inverter().trace(oa)
        truth = np.roll(raw, 1, axis=0) * 0.5 + 0.1  # something a readout can learn
        traced.append(Traced(f"c{i}", truth, raw, post, audio, np.zeros(len(oa)), []))
    specs = [ReadoutSpec(taps=2, hidden=0, alpha=1e-3), ReadoutSpec(taps=2, hidden=8, max_iter=30)]
    fitted, report = choose_readout(model, traced[:8], traced[8:], specs, bands=(0.0, 0.02), log=lambda _: None)
    assert fitted.readout is not None and len(report["candidates"]) == 3
    for c, oa in zip(traced[8:], oa_clips[8:], strict=True):
        inv = fitted.inverter()
        live = np.concatenate([inv.push(oa), inv.flush()])
        np.testing.assert_allclose(live, estimates(fitted, [c], fitted.readout, fitted.closure_band)[0][2], atol=1e-9)
    assert replace(fitted, readout=None).readout is None


@FEW_EPOCHS
def test_an_ensemble_readout_is_the_average_of_its_members():
    rng = np.random.default_rng(3)
    train = _traced(rng, 6, lambda raw, post, audio: np.tanh(raw) + 0.1 * audio[:, :DV])
    model = small_model(0)
    spec = ReadoutSpec(taps=2, hidden=5, max_iter=20)
    both = fit_readout(model, train, replace(spec, ensemble=2))
    members = [fit_readout(model, train, replace(spec, seed=s)) for s in (0, 1)]
    assert both.hidden == 10
    c = train[0]
    np.testing.assert_allclose(
        both.apply(c.raw, c.post, c.audio),
        np.mean([m.apply(c.raw, c.post, c.audio) for m in members], axis=0),
        atol=1e-10,
    )


def _speechlike_clip(rng: np.random.Generator, name: str):
    """A 1 s clip of amplitude-modulated harmonics (a voice-like spectrum) with a made-up lip track."""
    from types import SimpleNamespace

    t = np.arange(16000) / 16000
    x = sum(np.sin(2 * np.pi * 120 * k * t) / k for k in range(1, 30)) * (0.6 + 0.4 * np.sin(2 * np.pi * 3 * t))
    x = 0.05 * x + 0.003 * rng.standard_normal(len(t))
    params = rng.standard_normal((30, 4)) * 0.01
    return name, SimpleNamespace(samples=x.astype(np.float32), sample_rate_hz=16000, params=params), []


@pytest.mark.slow
def test_vtlp_copies_change_the_voice_not_the_lips():
    """trace_clips with warp 1 is the plain trace; a warped copy keeps the lips (truth) and the frame count and
    changes the audio rows the readout reads; vtlp_copies draws one warp per copy and clip, reproducibly."""
    from assets.modelfile import load_model
    from training.readout import VtlpConfig, trace_clips, vtlp_copies

    model = replace(load_model("default"), readout=None)
    rng = np.random.default_rng(4)
    clips = [_speechlike_clip(rng, "a"), _speechlike_clip(rng, "b")]
    plain = trace_clips(model, clips)
    same = trace_clips(model, clips, warps=[1.0, 1.0])
    warped = trace_clips(model, clips, warps=[1.1, 0.9])
    for p, s, w in zip(plain, same, warped):
        np.testing.assert_array_equal(s.audio, p.audio)
        np.testing.assert_array_equal(w.truth, p.truth)
        assert w.audio.shape == p.audio.shape and not np.allclose(w.audio, p.audio)
    assert [w.name for w in warped] == ["a-warp1.100", "b-warp0.900"]
    cfg = VtlpConfig(copies=2, warp_range=(0.88, 1.12), seed=0)
    copies = vtlp_copies(model, clips, cfg)
    assert len(copies) == 4 and [c.name for c in copies] == [c.name for c in vtlp_copies(model, clips, cfg)]
    assert all(0.88 <= float(c.name.rsplit("warp", 1)[1]) <= 1.12 for c in copies)
    with pytest.raises(ConfigError, match="warps"):
        trace_clips(model, clips, warps=[1.0])
    with pytest.raises(ConfigError, match="VTLP"):
        VtlpConfig(copies=1, warp_range=(0.7, 1.1))


def test_readout_command_refuses_a_bad_vtlp_range_before_any_work(tmp_path, capsys):
    """`facecast readout --vtlp-range` must be LOW,HIGH within the warp's range: refused with a message naming
    it, before the corpus is read, and no model is written."""
    from facecast.cli import main

    out = tmp_path / "m.npz"
    with pytest.raises(SystemExit) as exc:
        main(["readout", "default", "-o", str(out), "--vtlp-range", "1.1"])
    assert exc.value.code == 2 and "LOW,HIGH" in capsys.readouterr().err
    rc = main(["readout", "default", "-o", str(out), "--vtlp-range", "0.7,1.1", "--grid-s1", str(tmp_path)])
    assert rc != 0 and "VTLP" in capsys.readouterr().err and not out.exists()


def test_readout_command_names_a_corpus_folder_without_sentences(tmp_path, capsys):
    """`facecast readout --grid-s1 DIR` where DIR holds no GRID s1 sentences: one line naming the folder and
    the split, no traceback, no model written (it used to fail deep in the scoring on empty arrays)."""
    from facecast.cli import main

    out = tmp_path / "m.npz"
    rc = main(["readout", "default", "-o", str(out), "--grid-s1", str(tmp_path / "nowhere")])
    err = capsys.readouterr().err
    assert rc != 0 and f"{tmp_path / 'nowhere'}: no GRID s1 sentences (no such folder)" in err
    assert "Traceback" not in err and not out.exists()


def test_readout_command_refuses_corpus_with_grid_s1(tmp_path, capsys):
    """`facecast readout --corpus DIR --grid-s1 S1`: --corpus replaces GRID s1, so --grid-s1 beside it was silently
    ignored; now one line naming both options, exit 2, before any work. So is --choose-fraction without --corpus
    (it splits a corpus folder; GRID s1's split is fixed)."""
    from facecast.cli import main

    out = tmp_path / "m.npz"
    corpus, s1 = tmp_path / "mycorpus", tmp_path / "s1"
    rc = main(["readout", "default", "-o", str(out), "--corpus", str(corpus), "--grid-s1", str(s1)])
    err = capsys.readouterr().err
    assert rc == 2 and f"--corpus {corpus} and --grid-s1 {s1}" in err and len(err.strip().splitlines()) == 1
    rc = main(["readout", "default", "-o", str(out), "--choose-fraction", "0.3", "--grid-s1", str(s1)])
    err = capsys.readouterr().err
    assert rc == 2 and "--choose-fraction 0.3" in err and "--corpus" in err
    assert not out.exists()


def _inverter_traced(model, rng: np.random.Generator, n_clips: int, T: int = 50):
    """Clips of random audio rows through ``model``'s inverter, with a truth a readout can partly learn."""
    oa_clips = [rng.standard_normal((T, DA)) for _ in range(n_clips)]
    traced = []
    for i, oa in enumerate(oa_clips):
        raw, post, audio = model.inverter().trace(oa)
        truth = np.tanh(np.roll(raw, 2, axis=0)) * 0.5 + 0.1 * audio[:, :DV]
        traced.append(Traced(f"c{i}", truth, raw, post, audio, np.zeros(T), []))
    return oa_clips, traced


@FEW_EPOCHS
@pytest.mark.parametrize("hidden", [0, 5])
def test_loss_weight_one_is_the_unweighted_fit_bit_for_bit(hidden):
    """Weights of 1 (the default, four ones, or a mapping of ones) give exactly the weights of the plain fit:
    scikit-learn's Ridge, or training.readout.mlp_layers, on the unscaled targets."""
    from sklearn.linear_model import Ridge

    from training.readout import _features, mlp_layers

    rng = np.random.default_rng(5)
    model = small_model(1)
    train = _traced(rng, 6, lambda raw, post, audio: np.tanh(raw) + 0.1 * audio[:, :DV])
    spec = ReadoutSpec(taps=3, hidden=hidden, alpha=1e-3, max_iter=15, ensemble=2 if hidden else 1)
    phi = _features(spec, model, train)
    y = np.concatenate([c.truth for c in train])
    if hidden:
        w1, b1, w2, b2, _ = mlp_layers(spec, phi, y)
    else:
        lin = Ridge(alpha=spec.alpha).fit(phi, y)
        w1, b1, w2, b2 = np.zeros((phi.shape[1], 0)), np.zeros(0), lin.coef_.T, lin.intercept_
    for weight in [(1.0, 1.0, 1.0, 1.0), [1, 1, 1, 1], {"lip_stretch": 1.0}, {}]:
        ro = fit_readout(model, train, replace(spec, loss_weight=weight))
        for got, want in zip((ro.w1, ro.b1, ro.w2, ro.b2), (w1, b1, w2, b2), strict=True):
            np.testing.assert_array_equal(got, want)
        assert ro.metadata["loss_weight"] == dict.fromkeys(VISUAL_PARAMS, 1.0)


@FEW_EPOCHS
def test_a_weighted_readout_runs_live_as_its_nets_predict():
    """lip_stretch weighted 4, 8 taps, two nets: the stored readout, run by the live kernel (the inverter's
    compiled lag-0 push, before the output stage), equals the mean of the fitted nets' own predictions on the
    standardised inputs with lip_stretch divided back by sqrt(4), then the output stage; and the weight changed
    the fit."""
    from sklearn.preprocessing import StandardScaler

    from training.readout import _features, mlp_regressor

    rng = np.random.default_rng(6)
    model = replace(small_model(2), closure_band=0.0)
    oa_clips, traced = _inverter_traced(model, rng, 10)
    train, held = traced[:8], list(zip(oa_clips[8:], traced[8:], strict=True))
    spec = ReadoutSpec(taps=8, hidden=6, max_iter=25, ensemble=2, loss_weight={"lip_stretch": 4.0})
    ro = fit_readout(model, train, spec)
    assert ro.taps == 8 and ro.metadata["loss_weight"]["lip_stretch"] == 4.0

    phi = _features(spec, model, train)
    scaler = StandardScaler().fit(phi)
    scale = np.array([1.0, 2.0, 1.0, 1.0])
    y = np.concatenate([c.truth for c in train]) * scale
    nets = [mlp_regressor(spec, k).fit(scaler.transform(phi), y) for k in range(spec.ensemble)]
    live_model = replace(model, readout=ro)
    for oa, c in held:
        own = np.mean([net.predict(scaler.transform(_features(spec, model, [c]))) for net in nets], axis=0) / scale
        inv = live_model.inverter()
        live = np.concatenate([inv.push(oa), inv.flush()])
        # then the output stage (band 0: the closed-pose floor only), as the live path applies it
        np.testing.assert_allclose(live, live_model.output_stage(own.copy()), atol=1e-9)

    plain = fit_readout(model, train, replace(spec, loss_weight=(1.0, 1.0, 1.0, 1.0)))
    assert not np.allclose(plain.w2, ro.w2)


@pytest.mark.parametrize(
    ("weight", "named"),
    [
        ({"lip_strech": 4.0}, "lip_strech"),
        ({"lip_stretch": 0.0}, "lip_stretch=0.0"),
        ({"mouth_open": -1.0}, "mouth_open=-1.0"),
        ((1.0, float("nan"), 1.0, 1.0), "lip_stretch=nan"),
        ((1.0, 4.0, 1.0), "needs 4 values"),
        ("heavy", "four numbers"),
    ],
)
def test_bad_loss_weights_are_refused_naming_the_problem(weight, named):

    with pytest.raises(ConfigError, match="loss weight") as exc:
        ReadoutSpec(loss_weight=weight)
    assert named in str(exc.value)


def test_the_loss_weight_is_in_the_model_files_readout_metadata(tmp_path):
    """A weighted readout written by the model writer and read back keeps its weights in the metadata."""
    from assets.modelfile import load_model, save_model

    rng = np.random.default_rng(7)
    model = small_model(0)
    train = _traced(rng, 4, lambda raw, post, audio: raw * 0.5)
    ro = fit_readout(model, train, ReadoutSpec(taps=2, hidden=0, loss_weight=(2.0, 4.0, 1.0, 0.5)))
    back = load_model(save_model(tmp_path / "m.npz", replace(model, readout=ro)))
    assert back.readout is not None
    assert back.readout.metadata["loss_weight"] == dict(zip(VISUAL_PARAMS, (2.0, 4.0, 1.0, 0.5), strict=True))


def test_readout_command_refuses_bad_loss_weights_before_any_work(tmp_path, capsys):
    """`facecast readout --loss-weight`: not NAME=W is a usage error (exit 2); an unknown name or a weight <= 0
    is refused naming it, before the corpus is read (the folder holds no corpus), and no model is written."""
    from facecast.cli import main

    out = tmp_path / "m.npz"
    with pytest.raises(SystemExit) as exc:
        main(["readout", "default", "-o", str(out), "--loss-weight", "lip_stretch"])
    assert exc.value.code == 2 and "NAME=WEIGHT" in capsys.readouterr().err
    for bad, named in (("lip_strech=4", "lip_strech"), ("lip_stretch=0", "lip_stretch=0.0")):
        rc = main(["readout", "default", "-o", str(out), "--loss-weight", bad, "--grid-s1", str(tmp_path)])
        err = capsys.readouterr().err
        assert rc != 0 and named in err and "GRID" not in err and "Traceback" not in err and not out.exists()


def test_lip_closures_are_the_closed_frames_inside_speech_widened_to_a_stop():
    """The measured lips' own closures: runs of frames at mouth_open <= 0.01 between the first and last frame
    within 30 dB of the loudest; the closed rest before and after speech does not count, 0.011 is open, and a
    run shorter than 100 ms is widened to 100 ms about its centre."""
    from training.reallips import lip_closure_spans

    T = 60
    level = np.full(T, -80.0)
    level[10:41] = -20.0
    level[25] = -45.0  # a quieter frame inside speech is still inside it
    mo = np.full(T, 0.2)
    mo[:10] = mo[41:] = 0.0  # rest before and after the sentence
    mo[20:23] = 0.005  # frames 20, 21, 22
    mo[30] = 0.01  # at the tolerance: closed
    mo[35] = 0.011  # just above: open
    mo[38:41] = 0.0  # closed up to the last loud frame, then rest
    params = np.zeros((T, 4))
    params[:, VISUAL_PARAMS.index("mouth_open")] = mo
    spans = lip_closure_spans(params, level)
    want = [(20 / 30, 22 / 30), (30 / 30, 30 / 30), (38 / 30, 40 / 30)]
    assert [w for *_, w in spans] == ["lips"] * 3
    for (a, b, _), (fa, fb) in zip(spans, want, strict=True):
        centre, length = (fa + fb) / 2, max(fb - fa, 0.1)
        assert a == pytest.approx(centre - length / 2) and b == pytest.approx(centre + length / 2)


def _utt(uid: str):
    from training.corpus import Utterance

    return Utterance(uid, np.zeros(160, np.float32), 16000, np.zeros((1, 4)), (), "v", "en", "video", "g")


def test_a_corpus_splits_by_sentence_the_same_way_whatever_its_order():
    """split_corpus: floor(n f) utterances choose, spread over the corpus in order of id, the rest fit; the
    parts are disjoint, cover the corpus, and do not depend on the manifest's order."""
    from training.readout import split_corpus

    utts = [_utt(f"u{i:02d}") for i in range(23)]
    fit, choose = split_corpus(utts, choose_fraction=0.25)
    assert [u.id for u in choose] == ["u03", "u07", "u11", "u15", "u19"]  # floor(23 / 4) = 5, every 4th
    assert sorted(u.id for u in fit + choose) == [u.id for u in utts]
    fit2, choose2 = split_corpus(list(reversed(utts)), choose_fraction=0.25)
    assert [u.id for u in fit2] == [u.id for u in fit] and [u.id for u in choose2] == [u.id for u in choose]
    with pytest.raises(ConfigError, match=r"mycorpus: 19 utterances are too few.*3 to choose"):
        split_corpus(utts[:19], choose_fraction=0.2, where="mycorpus")


def _extracted_corpus(root, n: int) -> None:
    """A corpus laid out as `facecast extract` writes it (source "video", no phone labels): noise bursts
    (speech) between silences, the mouth open with the level and shut at two points inside the speech."""
    from training.corpus import write_manifest, write_utterance

    rng = np.random.default_rng(3)
    entries = []
    for i in range(n):
        rate, T = 16000, 45  # 1.5 s
        env = np.zeros(T)
        env[6:39] = 0.2 + 0.15 * np.abs(np.sin(np.arange(33) / (2 + i % 3)))
        env[[15, 16, 28]] = 0.0  # the lips shut inside the speech (a stop: the sound stops too)
        frame = np.arange(T * rate // 30) * 30 // rate  # each sample's video frame
        samples = (env[frame] * rng.standard_normal(len(frame)) + 1e-4 * rng.standard_normal(len(frame))).astype(
            np.float32
        )
        params = np.zeros((T, 4))
        params[:, VISUAL_PARAMS.index("mouth_open")] = env
        params[:, VISUAL_PARAMS.index("lip_stretch")] = 0.3 * env
        entries.append(
            write_utterance(
                root,
                utt_id=f"video-clip{i:02d}",
                samples=samples,
                sample_rate_hz=rate,
                params=params,
                phonemes=(),
                language="en",
                voice=f"video:clip{i:02d}",
                source="video",
                speaker_group=f"video:clip{i:02d}",
            )
        )
    write_manifest(root, entries, seed=None)


@FEW_EPOCHS
def test_readout_command_fits_and_chooses_on_an_extracted_corpus(tmp_path, capsys):
    """`facecast readout MODEL --corpus DIR`: a studio's own corpus (no GRID, no phone labels) gives a model
    whose readout is fitted and whose closure band is chosen on the corpus's choose part, with the lips' own
    closures; it says what it fitted on and where it wrote. A corpus too small to split is refused naming it."""
    from assets.modelfile import load_model, save_model
    from facecast.cli import main

    corpus = tmp_path / "mycorpus"
    _extracted_corpus(corpus, 10)
    model = save_model(tmp_path / "my.npz", small_model(0))  # closure band 0.02
    out = tmp_path / "my_ro.npz"
    args = ["readout", str(model), "--corpus", str(corpus), "-o", str(out), "--vtlp-copies", "0"]
    bands = ["--bands", "0.03,0.1", "--candidates", "2:state:0:1"]
    assert main([*args, *bands, "--choose-fraction", "0.4"]) == 0
    printed = capsys.readouterr().out
    assert "6 utterances fit, 4 choose" in printed and f"wrote {out}" in printed
    back = load_model(out)
    assert back.readout is not None and back.readout.taps == 2
    meta = back.metadata["readout"]
    assert meta["corpus"] == str(corpus) and meta["closures"] == {"phones": 0, "lips": 4}
    # the band is one offered, chosen on the choose part (not the model's 0.02), and recorded as chosen
    assert back.closure_band in (0.03, 0.1) and meta["band"] == back.closure_band

    small = tmp_path / "small"
    _extracted_corpus(small, 6)
    rc = main([*args[:3], str(small), "-o", str(tmp_path / "no.npz")])
    err = capsys.readouterr().err
    assert rc != 0 and str(small) in err and "too few" in err and "Traceback" not in err
    assert not (tmp_path / "no.npz").exists()


def test_the_band_is_the_best_r_among_bands_keeping_the_closures_else_the_widest():
    from training.reallips import LipScores

    def scores(r: float, closures: float) -> LipScores:
        return LipScores(
            r={"mouth_open": r},
            best_lag={},
            r_best={},
            nu={},
            closure_rate=closures,
            truth_closure_rate=1.0,
            n_closures=10,
            r_loudness=0.0,
            n_frames=100,
            per_clip={},
        )

    table = {0.02: scores(0.91, 0.85), 0.03: scores(0.90, 0.95), 0.04: scores(0.90, 0.97), 0.05: scores(0.88, 1.0)}
    called: list[float] = []

    def score(band: float) -> LipScores:
        called.append(band)
        return table[band]

    band, s = choose_band(score, bands=tuple(table), min_closure=0.9)
    # 0.02 has the best r but misses the closures; 0.03 and 0.04 tie: the first listed wins. Each band scored once.
    assert (band, s) == (0.03, table[0.03]) and called == list(table)
    band, s = choose_band(lambda b: table[b], bands=tuple(table), min_closure=1.01)
    assert (band, s) == (0.05, table[0.05])
