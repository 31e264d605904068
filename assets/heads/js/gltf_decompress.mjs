// Rewrite a glTF/GLB without the extensions facecast's reader cannot decode:
// EXT_meshopt_compression and KHR_draco_mesh_compression (decoded by glTF-Transform with the
// meshoptimizer and Draco decoders) and KHR_texture_basisu (KTX2 textures transcoded to RGBA by
// Binomial's Basis Universal transcoder, the basis_transcoder.wasm three.js ships for its KTX2Loader,
// then written as PNG by sharp). Rows are kept in the order the KTX2 file stores them, which
// KHR_texture_basisu defines as glTF's own (first row at v = 0), so UVs need no change.
// Usage: node gltf_decompress.mjs INPUT OUTPUT.glb   (exit 0 on success, 1 with a message)
import { readFileSync } from "node:fs";
import { createRequire } from "node:module";
import { dirname } from "node:path";
import { NodeIO } from "@gltf-transform/core";
import { ALL_EXTENSIONS } from "@gltf-transform/extensions";
import draco3d from "draco3dgltf";
import { MeshoptDecoder } from "meshoptimizer";
import sharp from "sharp";

const require = createRequire(import.meta.url);
const RGBA32 = 13; // basist::transcoder_texture_format::cTFRGBA32

async function basisTranscoder() {
  // The transcoder is an Emscripten script (not an ES module): evaluate it with the wasm bytes given.
  const js = require.resolve("three/examples/jsm/libs/basis/basis_transcoder.js");
  const wasmBinary = readFileSync(js.replace(/\.js$/, ".wasm"));
  const factory = new Function("require", "__filename", "__dirname", `${readFileSync(js, "utf8")}\nreturn BASIS;`)(
    require, js, dirname(js));
  const basis = await factory({ wasmBinary });
  basis.initializeBasis();
  return basis;
}

/** KTX2 bytes -> PNG bytes (level 0, layer 0, face 0). */
async function ktx2ToPng(basis, bytes, name) {
  const file = new basis.KTX2File(new Uint8Array(bytes));
  try {
    if (!file.isValid()) throw new Error(`${name}: not a valid KTX2 file`);
    const width = file.getWidth();
    const height = file.getHeight();
    if (!file.startTranscoding()) throw new Error(`${name}: the KTX2 transcoder cannot start`);
    const out = new Uint8Array(file.getImageTranscodedSizeInBytes(0, 0, 0, RGBA32));
    if (!file.transcodeImage(out, 0, 0, 0, RGBA32, 0, -1, -1)) throw new Error(`${name}: KTX2 transcoding failed`);
    return await sharp(Buffer.from(out.buffer), { raw: { width, height, channels: 4 } }).png().toBuffer();
  } finally {
    file.close();
    file.delete();
  }
}

const [input, output] = process.argv.slice(2);
try {
  await MeshoptDecoder.ready;
  const io = new NodeIO().registerExtensions(ALL_EXTENSIONS).registerDependencies({
    "draco3d.decoder": await draco3d.createDecoderModule(),
    "meshopt.decoder": MeshoptDecoder,
  });
  const doc = await io.read(input);
  const drop = ["EXT_meshopt_compression", "KHR_draco_mesh_compression"];
  const ktx = doc.getRoot().listTextures().filter((t) => t.getMimeType() === "image/ktx2");
  if (ktx.length) {
    const basis = await basisTranscoder();
    for (const [i, tex] of ktx.entries()) {
      tex.setImage(await ktx2ToPng(basis, tex.getImage(), tex.getName() || tex.getURI() || `texture ${i}`));
      tex.setMimeType("image/png");
      if (tex.getURI()) tex.setURI(tex.getURI().replace(/\.ktx2$/i, "") + ".png");
    }
    drop.push("KHR_texture_basisu");
  }
  for (const ext of doc.getRoot().listExtensionsUsed()) {
    if (drop.includes(ext.extensionName)) ext.dispose();
  }
  await io.write(output, doc);
} catch (err) {
  process.stderr.write(`${err.message}\n`);
  process.exit(1);
}
