"""Decompress glTF files whose meshes or textures need a decoder, with glTF-Transform (npm).

``EXT_meshopt_compression`` and ``KHR_draco_mesh_compression`` (what gltfpack and glTF-Transform
write) and ``KHR_texture_basisu`` (KTX2 textures) are decoded by ``assets/heads/js/gltf_decompress.mjs``,
a short Node script on well-kept npm packages (``package.json``; ``npm ci`` in the checkout), run as a
subprocess: ``@gltf-transform`` with the meshoptimizer and Draco decoders for the meshes, Basis
Universal's transcoder (``basis_transcoder.wasm``, shipped by ``three`` for its KTX2Loader) and
``sharp`` for KTX2 -> PNG. The plain GLB is cached under ``$FACECAST_CACHE/gltf/`` by the SHA-1 of
the input and of the script (a changed decoder re-decodes), written atomically (no partial file on failure).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from importlib import resources
from pathlib import Path

from assets.errors import MeshError
from assets.heads.cache import cache_dir

SCRIPT = "gltf_decompress.mjs"


def decompressed(path: Path, cache: Path | None = None) -> Path:
    """A plain copy of the glTF ``path`` (cached); MeshError naming the file when Node or the npm
    packages are missing or the decoder fails."""
    script = Path(str(resources.files("assets.heads").joinpath("js", SCRIPT)))
    digest = hashlib.sha1(path.read_bytes() + script.read_bytes()).hexdigest()
    root = (cache or cache_dir()) / "gltf"
    out = root / f"{digest}.glb"
    if out.is_file():
        return out
    node = shutil.which("node")
    if node is None:
        raise MeshError(
            f"{path}: this file is compressed (meshopt/Draco/KTX2) and decoding it needs Node.js "
            "(apt install nodejs) and `npm install` in the facecast checkout"
        )
    root.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=root, prefix=".tmp-", suffix=".glb")
    os.close(fd)
    try:
        res = subprocess.run(
            [node, str(script), str(path), tmp], capture_output=True, text=True, timeout=300, check=False
        )
        if res.returncode != 0:
            msg = res.stderr.strip().splitlines()[-1:] or ["unknown error"]
            hint = " (run `npm install` in the facecast checkout)" if "Cannot find package" in res.stderr else ""
            raise MeshError(f"{path}: cannot decompress this glTF: {msg[0]}{hint}")
        if res.stderr.strip():
            print(f"{path}: {res.stderr.strip()}", file=sys.stderr)
        os.replace(tmp, out)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise MeshError(f"{path}: cannot run the glTF decoder: {exc}") from exc
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return out
