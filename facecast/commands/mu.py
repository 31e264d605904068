"""``facecast mu``: paper 002 on GRID s1 - Motion Units, the MLP mapper (K chosen on val), the single-MLP
baseline and the HMM on the same targets, scored side by side."""

from __future__ import annotations

import argparse
from pathlib import Path

from facecast.commands.argtypes import ints


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "mu",
        help="Motion Units + the GMM-selected MLP mapper on GRID s1 (paper 002), scored beside the HMM",
        formatter_class=HelpFormatter,
        description="Learn Utterance Motion Units by PCA of the real lower-face landmark tracks of the GRID s1 "
        "sentences (from the shared `facecast extract` cache), train the audio-to-MUP mappers on the train split "
        "(the bank of K small MLPs picked by a Gaussian mixture, K chosen on the val split; one large MLP; the "
        "audio-visual HMM on the same MU parameters) and report R / nu / MSE (paper 002 eq. 6-8) on train and "
        "test. Writes OUT/mlp_mapper.npz (serve it with --mapper mlp), OUT/hmm_mups.npz, OUT/motion_units.npz, "
        "OUT/report.json, OUT/report.md and OUT/variance.png. GRID: Cooke, Barker, Cunningham, Shao 2006 (CC BY 4.0).",
    )
    p.add_argument(
        "--root", type=Path, default=None, help="GRID s1 folder (video/ + align/); default ../shared/data/video/grid_s1"
    )
    p.add_argument(
        "--cache-dir", type=Path, default=None, help="face-track cache (default $FACECAST_CACHE or ~/.cache/facecast)"
    )
    p.add_argument("-o", "--out", type=Path, required=True, help="output folder")
    p.add_argument(
        "--units", type=int, default=None, help="Utterance MUs to keep (default: fewest reaching --variance)"
    )
    p.add_argument("--variance", type=float, default=0.97, help="variance the kept MUs must explain")
    p.add_argument("--classes", type=ints, default=[4, 8, 16, 32, 44], help="candidate K (chosen on val)")
    p.add_argument("--hidden", type=int, default=20, help="hidden units per expert (the paper: 15-25)")
    p.add_argument("--baseline-hidden", type=int, default=600, help="hidden units of the single-MLP baseline (0: skip)")
    p.add_argument("--hmm-states", type=int, default=16, help="HMM states (0: skip the HMM)")
    p.add_argument("--hmm-mix", type=int, default=3, help="HMM mixtures per state")
    p.add_argument("--hmm-iters", type=int, default=20, help="Baum-Welch iterations")
    p.add_argument("--limit", type=int, default=None, help="use only the first N sentences (quick runs)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random choice")
    p.add_argument(
        "--stages-only",
        type=Path,
        default=None,
        metavar="MAPPER",
        help="refit only the expression second stages of MAPPER (an mlp_mapper.npz this command wrote, same data "
        "and settings); its speech bank is kept. Writes OUT/mlp_mapper.npz and OUT/expressions.json",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from assets.files import check_writable_folder
    from training.mu_train import MuTrainConfig, train_and_score

    check_writable_folder(args.out)  # before the training (it failed with a FileNotFoundError traceback)
    cfg = MuTrainConfig(
        units=args.units,
        variance=args.variance,
        classes=tuple(args.classes),
        hidden=args.hidden,
        baseline_hidden=args.baseline_hidden,
        hmm_states=args.hmm_states,
        hmm_mix=args.hmm_mix,
        hmm_iters=args.hmm_iters,
        limit=args.limit,
        seed=args.seed,
    )
    if args.stages_only is not None:
        from training.mu_train import refit_expression_stages

        refit_expression_stages(args.root, args.stages_only, args.out, cfg, cache_dir=args.cache_dir, say=print)
        return 0
    report = train_and_score(args.root, args.out, cfg, cache_dir=args.cache_dir, say=print)
    print(f"wrote {args.out}: K = {report['chosen_classes']}, test R mlp {report['test']['mlp']['R']:.3f}")
    return 0
