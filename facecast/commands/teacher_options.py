"""The teacher options ``facecast readout`` and ``facecast train`` share (``--teacher-espeak N`` ...): the same
names and meaning in both, one :class:`training.teacher.TeacherConfig` and one cache of the clips
(:func:`training.teacher.teacher_clips`)."""

from __future__ import annotations

import argparse


def add_teacher_options(p: argparse.ArgumentParser, into: str) -> None:
    """``--teacher-espeak/--teacher-festival/--teacher-seed/--teacher-n-best``; ``into`` names what the clips
    are added to in the help ("the readout's fit", "the HMM's training")."""
    p.add_argument(
        "--teacher-espeak",
        type=int,
        default=0,
        metavar="N",
        help=f"add N GRID-grammar sentences spoken by spread espeak-ng voices, rates and pitches to {into}, "
        "labelled with s1's real lips by unit selection over the train split (training/teacher.py; issue 10, "
        "docs/default_model.md; cached by the options under $FACECAST_CACHE/teacher); 0 = none",
    )
    p.add_argument(
        "--teacher-festival",
        type=int,
        default=0,
        metavar="N",
        help="the same with N sentences spoken by Festival's voices (kal, ked diphones, slt HTS); 0 = none",
    )
    p.add_argument("--teacher-seed", type=int, default=0, help="seeds the teacher sentences, voices, rates and levels")
    p.add_argument(
        "--teacher-n-best",
        type=int,
        default=5,
        metavar="K",
        help="unit sequences averaged per teacher label (as `facecast say --n-best`)",
    )


def teacher_config(args: argparse.Namespace):
    """The parsed options as a :class:`training.teacher.TeacherConfig` (a ConfigError for bad counts)."""
    from training.teacher import TeacherConfig

    return TeacherConfig(
        espeak=args.teacher_espeak, festival=args.teacher_festival, seed=args.teacher_seed, n_best=args.teacher_n_best
    )
