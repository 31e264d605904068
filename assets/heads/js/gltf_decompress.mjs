// Rewrite a glTF/GLB without the extensions facecast's reader cannot decode:
// EXT_meshopt_compression and KHR_draco_mesh_compression (decoded by glTF-Transform with the
// meshoptimizer and Draco decoders), KHR_texture_basisu (KTX2 -> PNG with KTX-Software's `ktx`
// tool when it is installed; otherwise the KTX2 textures are dropped and reported on stderr).
// Usage: node gltf_decompress.mjs INPUT OUTPUT.glb   (exit 0 on success, 1 with a message)
import { NodeIO } from "@gltf-transform/core";
import { ALL_EXTENSIONS } from "@gltf-transform/extensions";
import draco3d from "draco3dgltf";
import { MeshoptDecoder } from "meshoptimizer";

const [input, output] = process.argv.slice(2);
try {
  await MeshoptDecoder.ready;
  const io = new NodeIO().registerExtensions(ALL_EXTENSIONS).registerDependencies({
    "draco3d.decoder": await draco3d.createDecoderModule(),
    "meshopt.decoder": MeshoptDecoder,
  });
  const doc = await io.read(input);
  const drop = ["EXT_meshopt_compression", "KHR_draco_mesh_compression", "KHR_mesh_quantization"];
  let ktx = 0;
  for (const tex of doc.getRoot().listTextures()) {
    if (tex.getMimeType() === "image/ktx2") ktx++;
  }
  if (ktx) {
    let converted = false;
    try {
      const { ktxdecompress } = await import("@gltf-transform/cli");
      await doc.transform(ktxdecompress());
      converted = true;
    } catch (err) {
      process.stderr.write(`KTX2 textures not decoded (${err.message}); install KTX-Software's 'ktx' tool\n`);
    }
    if (!converted) {
      for (const tex of doc.getRoot().listTextures()) if (tex.getMimeType() === "image/ktx2") tex.dispose();
    }
    drop.push("KHR_texture_basisu");
  }
  for (const ext of doc.getRoot().listExtensionsUsed()) {
    if (drop.includes(ext.extensionName) && ext.extensionName !== "KHR_mesh_quantization") ext.dispose();
  }
  await io.write(output, doc);
} catch (err) {
  process.stderr.write(`${err.message}\n`);
  process.exit(1);
}
