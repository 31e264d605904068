// The head in three.js: built from the server's /head/mesh.json (+ /head/texture), moved by frames.
//
// The vertex order is the server's, so a frame's vertex deltas (x, y, z of each moving vertex, in
// the description's moving_vertices order) are added to the neutral positions directly, and each frame is
// lit with its own shape's normals (applyDeltas), as in the offline renderer.
// Back faces are drawn dark (the same mesh, both sides), so an open mouth shows a cavity.
//
// A head driven by its own morph targets (the description's head.morph) is moved the way an engine
// moves it: mesh.json carries the targets (sparse: the vertices any target moves, x, y, z per target),
// they become three.js morph attributes, and each frame of the "morph" kind sets
// morphTargetInfluences (one weight per target, in head.morph.names order); the GPU adds them. The targets' normal
// deltas (mesh.json's morph.normals, relative to computeVertexNormals' rest normals) become morph normals, which
// three.js blends the same way: without them every pose was lit with the rest normals (a lower lip turned down
// kept its rest shading, the open mouth's inner lip and chin crease looked flat).

import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { DEFAULT_BACKGROUND } from "./options.js";

// /head/* are private routes when the server has a token: pass the page's ?token= along.
function withToken(url) {
  const token = new URLSearchParams(location.search).get("token");
  if (!token) return url;
  return url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token);
}

function srgbToLinear(c) {
  // Vertex colours are authored in sRGB like textures; three.js lights in linear space.
  return c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4;
}

const BACK_FACE = [0x14 / 255, 0x04 / 255, 0x04 / 255].map((c) => c.toFixed(4)); // output (sRGB) colour of back faces

export class HeadView {
  /** background: a 0xRRGGBB colour behind the head, or null for a transparent canvas (the page behind shows:
   *  an avatar embedded in a chat page, a streaming tool's browser source over video). */
  constructor(canvas, { background = DEFAULT_BACKGROUND } = {}) {
    this.canvas = canvas;
    // premultipliedAlpha (three.js's default) composites the anti-aliased silhouette over the page without a halo.
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true, alpha: background === null });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.renderer.outputColorSpace = THREE.SRGBColorSpace;
    this.scene = new THREE.Scene();
    if (background === null) this.renderer.setClearColor(0x000000, 0);
    else this.scene.background = new THREE.Color(background);
    this.camera = new THREE.PerspectiveCamera(25, 1, 0.01, 1000);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.enableDamping = true;
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x443333, 0.9));
    const key = new THREE.DirectionalLight(0xffffff, 1.8);
    key.position.set(0.45, 0.45, 0.55);
    const fill = new THREE.DirectionalLight(0xffffff, 0.5);
    fill.position.set(-0.6, 0.0, 0.8);
    this.scene.add(key, fill);
    this.loading = null; // the last load (each waits for the one before)
    this.key = null; // what the loaded mesh is (to reload only when the server's head changes)
    this.mesh = null;
    this.moving = null; // Int32Array of moving vertex indices
    this.neutral = null; // Float32Array (n*3)
    this.peak = null; // Float32Array per moving vertex: largest |delta| seen (finds the mouth)
    this.lastPeak = 0; // largest |delta| of the frame shown (mesh units)
    this.morph = null; // {names, vertices: Int32Array, deltas: [Float32Array], reach: Float32Array} of a morph head
    this.maxWeight = null; // Float32Array per target: largest weight seen (finds the mouth)
    // Draw only when something changed (a frame, the camera, the size): software WebGL spends
    // most of the page's time drawing, and idle redraws delay the WebSocket messages.
    this.dirty = true;
    this.controls.addEventListener("change", () => { this.dirty = true; });
    this.resize();
    window.addEventListener("resize", () => this.resize());
  }

  resize() {
    const w = this.canvas.clientWidth || 640;
    const h = this.canvas.clientHeight || 480;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.dirty = true;
  }

  /** Load the head described by a viewer description's `head` (null clears it). Loads run one after another:
   *  two overlapping downloads (the head shown at rest while waiting, then the session's) each added a mesh. */
  load(head, base = "") {
    const next = (this.loading ?? Promise.resolve()).catch(() => {}).then(() => this.loadNow(head, base));
    this.loading = next;
    return next;
  }

  async loadNow(head, base) {
    const key = head ? `${head.mesh_json_url}|${head.vertex_count}|${head.moving_vertices.length}|${head.morph?.names?.length ?? 0}` : null;
    const wantMorph = Boolean(head && head.morph);
    if (head && key === this.key && wantMorph === Boolean(this.morph)) {
      this.setMoving(head);
      return;
    }
    if (this.mesh) {
      this.scene.remove(this.mesh.group);
      this.mesh.geometry.dispose();
      this.mesh = null;
    }
    this.key = null;
    this.morph = null;
    this.dirty = true;
    if (!head) return;
    const res = await fetch(withToken(base + head.mesh_json_url), { cache: "no-store" });
    if (!res.ok) throw new Error(`head mesh: HTTP ${res.status}`);
    const m = await res.json();
    const geometry = new THREE.BufferGeometry();
    this.neutral = new Float32Array(m.vertices);
    geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(m.vertices), 3));
    geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(m.triangles), 1));
    geometry.computeVertexNormals();
    if (wantMorph) {
      if (!m.morph || m.morph.names.join("\n") !== head.morph.names.join("\n")) {
        throw new Error("head mesh: its morph targets do not match the description");
      }
      this.morph = this.setMorphTargets(geometry, m.morph, m.vertices.length / 3);
    }
    const material = new THREE.MeshStandardMaterial({ roughness: 0.75, metalness: 0.0 });
    if (m.colors) {
      geometry.setAttribute("color", new THREE.BufferAttribute(new Float32Array(m.colors.map(srgbToLinear)), 3));
      material.vertexColors = true;
    } else {
      material.color = new THREE.Color(0.8, 0.62, 0.52).convertSRGBToLinear();
    }
    if (m.uvs) geometry.setAttribute("uv", new THREE.BufferAttribute(new Float32Array(m.uvs), 2));
    if (m.uvs && head.texture_url) {
      const tex = await new THREE.TextureLoader().loadAsync(withToken(base + head.texture_url));
      tex.flipY = false; // texture row 0 is v = 0 (as the offline renderer samples it)
      // UVs beyond [0, 1] repeat, as glTF's default sampler and the offline renderer have it (three.js clamps).
      tex.wrapS = tex.wrapT = THREE.RepeatWrapping;
      tex.colorSpace = THREE.SRGBColorSpace;
      material.map = tex;
      // The texture alone paints the head (the skin colour above tinted it, darker and redder than the offline
      // renderer's); colours with a texture multiply it (glTF's COLOR_0): a textured head's teeth darkened by depth.
      material.color = new THREE.Color(1, 1, 1);
      material.vertexColors = Boolean(m.colors);
      // A see-through material's texels (eyelashes, a cornea) come with alpha 0 (assets.heads.mesh.CUTOUT_ALPHA);
      // an opaque head's texture has no alpha channel, so the test cuts nothing there.
      material.alphaTest = 0.5;
    }
    // One mesh drawn on both sides, back faces painted dark in the fragment shader: a second mesh
    // for the back faces would run the vertex work (the morph targets' loop) twice.
    material.side = THREE.DoubleSide;
    material.onBeforeCompile = (shader) => {
      shader.fragmentShader = shader.fragmentShader.replace(
        "#include <dithering_fragment>",
        "#include <dithering_fragment>\n  if (!gl_FrontFacing) gl_FragColor = vec4(BACK_FACE, 1.0);",
      ).replace("void main() {", `const vec3 BACK_FACE = vec3(${BACK_FACE.join(", ")});\nvoid main() {`);
    };
    const front = new THREE.Mesh(geometry, material);
    front.frustumCulled = false; // deltas move vertices past the bounding sphere
    this.meshes = [front];
    const group = new THREE.Group();
    group.add(front);
    this.scene.add(group);
    this.mesh = { group, geometry };
    this.key = key;
    this.setMoving(head);
    this.frame();
  }

  setMoving(head) {
    this.moving = Int32Array.from(head.moving_vertices);
    this.peak = new Float32Array(this.moving.length);
    if (this.morph) this.maxWeight = new Float32Array(this.morph.names.length);
  }

  /** Dense three.js morph attributes (relative: displacement per unit weight) from mesh.json's sparse
   *  targets; returns what applyWeights needs. */
  setMorphTargets(geometry, morph, n) {
    const vertices = Int32Array.from(morph.vertices);
    const deltas = [];
    const reach = new Float32Array(morph.names.length); // largest |displacement| of each target
    geometry.morphAttributes.position = morph.deltas.map((flat, j) => {
      const sparse = Float32Array.from(flat);
      const dense = new Float32Array(3 * n);
      for (let i = 0; i < vertices.length; i++) {
        const o = 3 * vertices[i];
        dense[o] = sparse[3 * i];
        dense[o + 1] = sparse[3 * i + 1];
        dense[o + 2] = sparse[3 * i + 2];
        reach[j] = Math.max(reach[j], Math.abs(sparse[3 * i]), Math.abs(sparse[3 * i + 1]), Math.abs(sparse[3 * i + 2]));
      }
      deltas.push(sparse);
      return new THREE.BufferAttribute(dense, 3);
    });
    const turned = Int32Array.from(morph.normals.vertices);
    geometry.morphAttributes.normal = morph.normals.deltas.map((flat) => {
      const dense = new Float32Array(3 * n);
      for (let i = 0; i < turned.length; i++) {
        for (let c = 0; c < 3; c++) dense[3 * turned[i] + c] = flat[3 * i + c];
      }
      return new THREE.BufferAttribute(dense, 3);
    });
    geometry.morphTargetsRelative = true;
    return { names: morph.names, vertices, deltas, reach };
  }

  /** Show one frame of the head's own morph-target weights (values: one per target, names order). */
  applyWeights(values) {
    if (!this.mesh || !this.morph) return;
    let peak = 0;
    for (const mesh of this.meshes) {
      const inf = mesh.morphTargetInfluences;
      for (let j = 0; j < inf.length; j++) inf[j] = values[j];
    }
    for (let j = 0; j < values.length; j++) {
      peak += Math.abs(values[j]) * this.morph.reach[j]; // a bound on the largest vertex displacement
      if (values[j] > this.maxWeight[j]) this.maxWeight[j] = values[j];
    }
    this.lastPeak = peak;
    this.dirty = true;
  }

  /** The influences three.js draws with (automation: they must equal the streamed weights). */
  influences() {
    return this.meshes && this.morph ? Array.from(this.meshes[0].morphTargetInfluences) : null;
  }

  /** Point the camera at the face: the moving vertices' box (the whole mesh when it is at most 3 times
   *  as tall: a head), seen from +z (glTF's forward), y up. */
  frame() {
    const pos = this.neutral;
    const box = new THREE.Box3();
    const v = new THREE.Vector3();
    const n = this.moving.length || pos.length / 3;
    for (let j = 0; j < n; j++) box.expandByPoint(v.fromArray(pos, 3 * (this.moving.length ? this.moving[j] : j)));
    // A head (not a full-body avatar) is shown whole: its own targets may move the mouth region only.
    const all = new THREE.Box3();
    for (let i = 0; i < pos.length; i += 3) all.expandByPoint(v.fromArray(pos, i));
    if (all.getSize(new THREE.Vector3()).y <= 3 * box.getSize(new THREE.Vector3()).y) box.copy(all);
    const centre = box.getCenter(new THREE.Vector3());
    const size = box.getSize(new THREE.Vector3());
    const height = Math.max(size.y, size.x / this.camera.aspect);
    const dist = (1.25 * height) / (2 * Math.tan((this.camera.fov * Math.PI) / 360));
    this.camera.near = dist / 50;
    this.camera.far = dist * 50;
    this.camera.position.set(centre.x, centre.y, centre.z + dist + size.z / 2);
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(centre);
    this.controls.update();
    this.dirty = true;
  }

  /** Show one frame of vertex deltas: values (3 * moving) in mesh units. */
  applyDeltas(values) {
    if (!this.mesh) return;
    const attr = this.mesh.geometry.getAttribute("position");
    const out = attr.array;
    const base = this.neutral;
    const moving = this.moving;
    let peak = 0;
    for (let j = 0; j < moving.length; j++) {
      const o = 3 * moving[j];
      const dx = values[3 * j], dy = values[3 * j + 1], dz = values[3 * j + 2];
      out[o] = base[o] + dx;
      out[o + 1] = base[o + 1] + dy;
      out[o + 2] = base[o + 2] + dz;
      const a = Math.max(Math.abs(dx), Math.abs(dy), Math.abs(dz));
      if (a > this.peak[j]) this.peak[j] = a;
      if (a > peak) peak = a;
    }
    this.lastPeak = peak;
    attr.needsUpdate = true;
    // Light the frame as its own shape (as the offline renderer does): with the rest pose's normals an
    // open mouth's inside stays lit and a turned lip keeps its rest shading. ~1 ms for 17k triangles.
    this.mesh.geometry.computeVertexNormals();
    this.dirty = true;
  }

  /** Largest angle (degrees) between the normals drawn and those of the shape drawn (automation: 0
   *  when every frame is lit as its own shape). */
  normalsLag() {
    if (!this.mesh) return null;
    const fresh = this.mesh.geometry.clone();
    fresh.computeVertexNormals();
    const a = this.mesh.geometry.getAttribute("normal").array;
    const b = fresh.getAttribute("normal").array;
    let worst = 0;
    for (let i = 0; i < a.length; i += 3) {
      const dot = a[i] * b[i] + a[i + 1] * b[i + 1] + a[i + 2] * b[i + 2];
      worst = Math.max(worst, Math.acos(Math.min(1, Math.max(-1, dot))));
    }
    fresh.dispose();
    return (worst * 180) / Math.PI;
  }

  /** A morph head's lighting at the shown influences, over the vertices the frame moves most (>= 10% of the
   *  largest displacement: lips, jaw, chin), as {count, turned, lag, restLag} (automation): turned, the angles
   *  (degrees, median and 99th percentile) between the normals three.js draws (the rest normals plus the
   *  influences times the morph normals, as its morphnormal_vertex shader adds them) and the rest normals; lag,
   *  between the drawn normals and those computeVertexNormals gives the blended shape; restLag, between the rest
   *  normals and the blended shape's. */
  morphNormals() {
    if (!this.mesh || !this.morph) return null;
    const geo = this.mesh.geometry;
    const inf = this.meshes[0].morphTargetInfluences;
    const rest = geo.getAttribute("normal").array;
    const pos = geo.getAttribute("position").array;
    const n = pos.length / 3;
    const shape = new Float32Array(pos);
    const drawn = new Float32Array(rest);
    const dn = geo.morphAttributes.normal ?? [];
    geo.morphAttributes.position.forEach((attr, j) => {
      if (!inf[j]) return;
      for (let k = 0; k < 3 * n; k++) shape[k] += inf[j] * attr.array[k];
      if (dn[j]) for (let k = 0; k < 3 * n; k++) drawn[k] += inf[j] * dn[j].array[k];
    });
    const fresh = new THREE.BufferGeometry();
    fresh.setAttribute("position", new THREE.BufferAttribute(shape, 3));
    fresh.setIndex(geo.getIndex());
    fresh.computeVertexNormals();
    const truth = fresh.getAttribute("normal").array;
    fresh.dispose();
    const moved = new Float32Array(n);
    let top = 0;
    for (let i = 0; i < n; i++) {
      moved[i] = Math.hypot(shape[3 * i] - pos[3 * i], shape[3 * i + 1] - pos[3 * i + 1], shape[3 * i + 2] - pos[3 * i + 2]);
      top = Math.max(top, moved[i]);
    }
    const angle = (a, b, i) => {
      const o = 3 * i;
      const dot = a[o] * b[o] + a[o + 1] * b[o + 1] + a[o + 2] * b[o + 2];
      const len = Math.hypot(a[o], a[o + 1], a[o + 2]) * Math.hypot(b[o], b[o + 1], b[o + 2]) || 1;
      return (Math.acos(Math.min(1, Math.max(-1, dot / len))) * 180) / Math.PI;
    };
    const turned = [], lag = [], restLag = [];
    for (let i = 0; i < n; i++) {
      if (!(top > 0) || moved[i] < 0.1 * top) continue;
      turned.push(angle(drawn, rest, i));
      lag.push(angle(drawn, truth, i));
      restLag.push(angle(rest, truth, i));
    }
    const stats = (a) => {
      const s = Float64Array.from(a).sort();
      const at = (q) => (s.length ? s[Math.min(s.length - 1, Math.floor(q * s.length))] : null);
      return { median: at(0.5), p99: at(0.99) };
    };
    return { count: turned.length, turned: stats(turned), lag: stats(lag), restLag: stats(restLag) };
  }

  /** Draw if anything changed since the last draw (call once per animation frame). */
  render() {
    this.controls.update(); // advances damping; fires "change" while the camera still moves
    if (!this.dirty) return;
    this.dirty = false;
    this.renderer.render(this.scene, this.camera);
  }

  /** Per-vertex peaks of a morph head from the largest weights seen (the moving vertices are the
   *  targets' vertices: the server's moving_vertices are the same set, in the same order). */
  morphPeaks() {
    const { vertices, deltas } = this.morph;
    this.moving = vertices;
    this.peak = new Float32Array(vertices.length);
    for (let j = 0; j < deltas.length; j++) {
      const w = this.maxWeight[j];
      if (!(w > 0)) continue;
      const d = deltas[j];
      for (let i = 0; i < vertices.length; i++) {
        const a = w * Math.max(Math.abs(d[3 * i]), Math.abs(d[3 * i + 1]), Math.abs(d[3 * i + 2]));
        if (a > this.peak[i]) this.peak[i] = a;
      }
    }
  }

  /** Screen box {x, y, width, height} (CSS pixels, canvas-relative) of the vertices that moved most
   *  so far (>= 25% of the largest movement): where the mouth is on the canvas. */
  mouthBox() {
    if (this.morph) this.morphPeaks();
    if (!this.mesh || !this.peak.length) return null;
    const top = this.peak.reduce((a, b) => Math.max(a, b), 0);
    if (!(top > 0)) return null;
    const rect = this.canvas.getBoundingClientRect();
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    const v = new THREE.Vector3();
    for (let j = 0; j < this.moving.length; j++) {
      if (this.peak[j] < 0.25 * top) continue;
      v.fromArray(this.neutral, 3 * this.moving[j]).project(this.camera);
      const x = ((v.x + 1) / 2) * rect.width;
      const y = ((1 - v.y) / 2) * rect.height;
      x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y);
    }
    const pad = 0.25 * Math.max(x1 - x0, y1 - y0);
    return { x: rect.left + x0 - pad, y: rect.top + y0 - pad, width: x1 - x0 + 2 * pad, height: y1 - y0 + 2 * pad };
  }
}
