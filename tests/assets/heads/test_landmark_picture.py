"""The landmarks picture (`facecast rig HEAD --show-landmarks PNG`): every number readable. The numbers of the
midline points (nose, the four lip midpoints, chin) were put beside their points, 0.05-0.1 IOD apart on a mouth,
and 7, 9 and 10 were drawn over one another."""

from __future__ import annotations

import itertools

import numpy as np

from assets.heads.plot import LABEL_GAP_IOD, _label_places
from realtime_core.face import MouthLandmarks, face_frame


def test_landmark_numbers_do_not_overlap_on_the_builtin_and_lee_perry_smith(builtin_head, shared_data):
    from assets.heads.landmarks import read_landmarks, shipped_landmarks
    from assets.heads.mesh import load_mesh
    from assets.heads.plot import LANDMARK_HELP

    lee = shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb"
    heads = {
        "builtin": (builtin_head.mesh.vertices, dict(builtin_head.landmarks)),
        "lee": (load_mesh(lee).vertices, read_landmarks(shipped_landmarks(lee))),
    }
    for name, (vertices, spec) in heads.items():
        names = [k for k in LANDMARK_HELP if k in spec]
        pv = np.stack([np.asarray(vertices[int(spec[k])], dtype=np.float64) for k in names])
        fr = face_frame(pv, MouthLandmarks(**{k: names.index(k) for k in MouthLandmarks.__dataclass_fields__}))
        p = (pv - fr.origin) @ fr.axes.T / fr.iod  # as the picture draws them (IOD, x to the viewer's right)
        places = np.array(_label_places(p[:, :2]))
        # a number is about 0.15 IOD wide and 0.1 high at the picture's scale: no two boxes meet
        for i, j in itertools.combinations(range(len(names)), 2):
            dx, dy = np.abs(places[i] - places[j])
            assert dx >= 0.3 or dy >= 0.9 * LABEL_GAP_IOD, (name, names[i], names[j], places[i], places[j])
        # and no number covers a landmark other than its own
        for i, j in itertools.permutations(range(len(names)), 2):
            dx, dy = np.abs(places[i] - p[j, :2])
            assert dx >= 0.1 or dy >= 0.06, (name, names[i], "covers", names[j])
