"""The head options every command that takes ``--head`` shares, and the one call that resolves them."""

from __future__ import annotations

import argparse
import sys
import time


def add_head_options(p: argparse.ArgumentParser, *, head: bool = True, help_head: str | None = None) -> None:
    """--head, --head-part, --landmarks, --head-mode, --target-map."""
    if head:
        p.add_argument(
            "--head",
            default="builtin",
            help=help_head or "'builtin', a rig file (.npz) or a head mesh (glb/gltf/vrm/obj/ply)",
        )
    p.add_argument(
        "--head-part",
        action="append",
        default=[],
        metavar="MESH",
        help="another mesh file of the same head (eyes, teeth, tongue delivered separately); repeatable. "
        "Eyes and upper teeth stay with the skull, lower teeth and tongue move with the jaw",
    )
    p.add_argument(
        "--landmarks",
        default=None,
        help="landmarks JSON for a head mesh rigged by retargeting (default: shipped for known heads, "
        "else found automatically; see docs/heads.md)",
    )
    p.add_argument(
        "--head-mode",
        choices=("auto", "morph", "retarget"),
        default="auto",
        help="auto: drive the head's own morph targets when it has enough mouth targets, else "
        "retarget; morph: own targets only; retarget: always the Sec. 5 rig",
    )
    p.add_argument(
        "--target-map",
        default=None,
        help="JSON mapping the head's morph-target names to ARKit names / visemes (docs/heads.md)",
    )


def resolve_from_args(args: argparse.Namespace, spec: object = None):
    """The :class:`assets.heads.head.Head` the options name (``spec`` overrides ``args.head``)."""
    from assets.heads.head import resolve_head
    from clients.render.landmarks import find_landmarks

    name = str(spec if spec is not None else args.head)
    start = time.monotonic()

    def progress(line: str) -> None:  # a mesh not in the rig cache is rigged now: seconds to minutes
        print(f"head {name}: {line} ({time.monotonic() - start:.0f} s)", file=sys.stderr, flush=True)

    head = resolve_head(
        name,
        landmarks=args.landmarks,
        mode=args.head_mode,
        target_map=args.target_map,
        landmark_finder=find_landmarks,
        parts=tuple(getattr(args, "head_part", ()) or ()),
        progress=progress,
    )
    if name != "builtin":  # (the built-in head passes: tests/assets/heads)
        warn_failing_checks(head, name)
    return head


def warn_failing_checks(head, name: str) -> None:
    """One line on stderr when ``head`` fails the rig checks (the checks ``facecast rig`` refuses a rig
    for); the head is used anyway. A rig that records its checks (meta "checks": a mesh rigged now or
    read from the rig cache, a ``facecast rig`` file) is not measured again; heads whose landmarks are
    unknown (own targets, none in the file) are not checked here (finding them means rendering the face)."""
    from assets.heads.head import head_checks
    from realtime_core.errors import FacecastError

    kept = head.rig.meta.get("checks")
    if isinstance(kept, dict) and "passed" in kept and "failures" in kept:
        # Measured when the head was rigged (assets.heads.head.rig_checked): a first rig measured them twice.
        passed, failures = bool(kept["passed"]), [str(f) for f in kept["failures"]]
    elif not head.rig.meta.get("landmarks"):
        return
    else:
        try:
            report = head_checks(head)
        except FacecastError:
            return
        passed, failures = report.passed, list(report.failures)
    if not passed:
        print(
            f"facecast: warning: {name} fails the rig checks ({'; '.join(failures)}); used anyway. "
            f"{_what_it_means(failures)}: check the landmarks (facecast rig HEAD --show-landmarks PNG), give "
            "--landmarks, or try --head-mode morph/retarget (docs/heads.md, Rig checks)",
            file=sys.stderr,
        )


# What a user sees of each failure that does not tear the mouth (realtime_core.face.checks.check_rig's wording).
_MILD = (
    ("apart at closure", "the lips may not meet at /p b m/"),
    ("the lips part by", "the mouth opens less than the speech asks"),
)


def _what_it_means(failures: list[str]) -> str:
    """The sentence after the figures: what the failures look like. A head whose only failures are mild (a VRM
    avatar's vowels cannot press its lips together: 0.011 IOD apart at closure) was told its mouth "may tear or
    fold", which none of them does."""
    mild = [next((says for key, says in _MILD if key in f), None) for f in failures]
    if failures and all(mild):
        said = list(dict.fromkeys(m for m in mild if m))
        return "; ".join(said)[0].upper() + "; ".join(said)[1:]
    return "The mouth may tear or fold"
