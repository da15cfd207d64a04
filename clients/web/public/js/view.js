// The 3D view: the watched surface (smooth shading, field colours), the
// control mesh overlay, pins and loads, the tool cursor; orbit, pan, zoom.
// Only drawing and local ray casts for the cursor: picking for commands is
// the server's Pick (material coordinates), geometry comes decoded from the
// Watch stream (surface.js).

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { colorize, fieldRange } from './colormap.js';
import { vertexQuads, creasedNormals, matcapPixels } from './shading.js';
import { BrushCursor } from './cursor.js';
import { PRESETS, frameSphere, aboveGround } from './camera.js';

const SURFACE_COLOR = 0xd8cbb6;
// Highlighted control faces (showFaces): taken, refused, merge's first.
const FACE_COLORS = { ok: 0x2fe07a, refused: 0xff5a4a, chosen: 0x58a6ff };

// Whether WebGL runs on the CPU (SwiftShader, llvmpipe).
function softwareRenderer() {
  try {
    const gl = document.createElement('canvas').getContext('webgl');
    if (!gl) return false;
    const ext = gl.getExtension('WEBGL_debug_renderer_info');
    const name = ext ? gl.getParameter(ext.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
    gl.getExtension('WEBGL_lose_context')?.loseContext();
    return /swiftshader|llvmpipe|software/i.test(String(name));
  } catch (e) {
    return false;
  }
}

export class View {
  constructor(container) {
    this.container = container;
    // Multisampling costs a software renderer (SwiftShader: no GPU) most of
    // its frame time; ?aa=1 / ?aa=0 overrides.
    const aa = new URLSearchParams(location.search).get('aa');
    this.software = softwareRenderer();
    const antialias = aa === null ? !this.software : aa === '1';
    this.renderer = new THREE.WebGLRenderer({ antialias, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.renderer.setClearColor(0x20242c);
    container.appendChild(this.renderer.domElement);
    this.canvas = this.renderer.domElement;

    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.001, 1000);
    // The scenes are z-up (gravity along -z, the ground at z = 0).
    this.camera.up.set(0, 0, 1);
    this.camera.position.set(6, -8, 5);
    this.scene.add(this.camera);

    // The boundary is closed and its quads face outward: front faces only.
    // A matcap (shading.js: hemisphere plus key light painted on a sphere)
    // reads the same in software WebGL as on a GPU, with no lights to
    // compute, and creased normals keep sharp edges free of dark bands.
    const matcap = new THREE.DataTexture(matcapPixels(128), 128, 128);
    matcap.colorSpace = THREE.SRGBColorSpace;
    matcap.needsUpdate = true;
    // Pushed back a little in depth: control edges lying on the surface
    // (flat faces) draw in front of it.
    this.surfaceMaterial = new THREE.MeshMatcapMaterial({ color: SURFACE_COLOR, matcap, side: THREE.FrontSide,
      polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 2 });
    this.mesh = null;
    this.geometry = null;
    this.overlay = new THREE.Group();
    this.scene.add(this.overlay);
    this.controlLines = null;
    this.markers = new THREE.Group();
    this.scene.add(this.markers);
    // Control faces under the pointer (Extrude, Merge: hover.js), drawn
    // over the surface: a control face lies a little outside the smooth
    // surface it makes, or inside it where the solid is concave.
    this.faceGroup = new THREE.Group();
    this.scene.add(this.faceGroup);
    this.faceMaterials = {};
    for (const [kind, color] of Object.entries(FACE_COLORS)) {
      this.faceMaterials[kind] = {
        fill: new THREE.MeshBasicMaterial({ color, transparent: true, opacity: 0.55, depthTest: false,
          depthWrite: false, side: THREE.DoubleSide }),
        line: new THREE.LineBasicMaterial({ color, depthTest: false }),
      };
    }
    this.cursor = new BrushCursor();
    this.scene.add(this.cursor.group);
    this.grid = null;
    this.groundZ = null;        // the ground plane's height (the solid's lowest point when framed)

    this.raycaster = new THREE.Raycaster();
    this.field = null;          // the coloured field's name, or null
    this.range = null;
    this.framed = false;
    // Drawn only when something changed (a frame, the camera, an overlay):
    // an idle viewer leaves the CPU to everything else.
    this.needsRender = true;
    this.resize();
    window.addEventListener('resize', () => this.resize());
  }

  // Call after the app's own pointer listeners are on the canvas, so the
  // app can switch orbiting off for a press that starts a tool.
  attachControls() {
    this.controls = new OrbitControls(this.camera, this.canvas);
    this.controls.enableDamping = false;
    this.controls.addEventListener('change', () => {
      this.keepAboveGround();
      this.needsRender = true;
    });
    // Middle orbits too, so a tool's left button never has to.
    this.controls.mouseButtons = { LEFT: THREE.MOUSE.ROTATE, MIDDLE: THREE.MOUSE.ROTATE, RIGHT: THREE.MOUSE.PAN };
  }

  // The orbit stays above the ground plane (camera.js aboveGround).
  keepAboveGround() {
    if (this.groundZ === null || !this.controls) return;
    const r = this.geometry && this.geometry.boundingSphere ? this.geometry.boundingSphere.radius : 1;
    const c = this.camera.position;
    const t = this.controls.target;
    const m = aboveGround(c, t, this.groundZ, 0.03 * r);
    if (!m.changed) return;
    c.set(m.eye.x, m.eye.y, m.eye.z);
    t.set(m.target.x, m.target.y, m.target.z);
    this.camera.lookAt(t);
  }

  resize() {
    const w = this.container.clientWidth || 800;
    const h = this.container.clientHeight || 600;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.needsRender = true;
  }

  // Updates the surface from a SurfaceDecoder after a frame. The mesh has
  // one vertex per quad corner (4 per quad), so a vertex on a sharp edge
  // gets a normal per side (shading.js creasedNormals).
  updateSurface(decoder) {
    const n = decoder.vertexCount;
    // Several frames may have arrived since the last draw: rebuild on any
    // topology change among them, and copy every position.
    const topology = decoder.topologySerial !== this.topologySerial || !this.geometry ||
      this.vertexCount !== n;
    this.topologySerial = decoder.topologySerial;
    if (topology) this.rebuildMesh(decoder.quads, n);
    const q = this.quads;
    const p = decoder.positions;
    const pos = this.geometry.getAttribute('position');
    const arr = pos.array;
    for (let k = 0; k < q.length; ++k) {
      const v = 3 * q[k];
      arr[3 * k] = p[v]; arr[3 * k + 1] = p[v + 1]; arr[3 * k + 2] = p[v + 2];
    }
    pos.needsUpdate = true;
    const normal = this.geometry.getAttribute('normal');
    creasedNormals(p, q, this.adjacency, normal.array, this.scratch);
    normal.needsUpdate = true;
    this.needsRender = true;
    this.geometry.computeBoundingSphere();  // ray casts test it first
    this.updateColors(decoder);
    if (!this.framed && n > 0) {
      this.resetCamera();
      this.framed = true;
    }
  }

  rebuildMesh(quads, n) {
    if (this.mesh) {
      this.scene.remove(this.mesh);
      this.geometry.dispose();
    }
    this.quads = quads;
    this.vertexCount = n;
    this.adjacency = vertexQuads(quads, n);
    const corners = quads.length;
    this.scratch = { area: new Float32Array(3 * (corners >> 2)), unit: new Float32Array(3 * (corners >> 2)) };
    this.vertexColors = new Float32Array(3 * n);
    this.geometry = new THREE.BufferGeometry();
    this.geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3 * corners), 3));
    this.geometry.setAttribute('normal', new THREE.BufferAttribute(new Float32Array(3 * corners), 3));
    this.geometry.setAttribute('color', new THREE.BufferAttribute(new Float32Array(3 * corners), 3));
    const index = new Uint32Array((corners / 4) * 6);
    for (let i = 0, j = 0; i < corners; i += 4) {
      index[j++] = i; index[j++] = i + 1; index[j++] = i + 2;
      index[j++] = i; index[j++] = i + 2; index[j++] = i + 3;
    }
    this.geometry.setIndex(new THREE.BufferAttribute(index, 1));
    this.mesh = new THREE.Mesh(this.geometry, this.surfaceMaterial);
    this.scene.add(this.mesh);
  }

  setField(name) {
    this.field = name;
    this.range = null;
  }

  updateColors(decoder) {
    const values = this.field ? decoder.fields[this.field] : null;
    const useColors = Boolean(values && values.length === decoder.vertexCount);
    if (this.surfaceMaterial.vertexColors !== useColors) {
      this.surfaceMaterial.vertexColors = useColors;
      this.surfaceMaterial.color.set(useColors ? 0xffffff : SURFACE_COLOR);
      this.surfaceMaterial.needsUpdate = true;
    }
    if (!useColors) {
      this.range = null;
      return;
    }
    this.range = fieldRange(this.field, values);
    colorize(values, this.range, this.vertexColors);
    const color = this.geometry.getAttribute('color');
    const out = color.array;
    const vc = this.vertexColors;
    const q = this.quads;
    for (let k = 0; k < q.length; ++k) {
      const v = 3 * q[k];
      out[3 * k] = vc[v]; out[3 * k + 1] = vc[v + 1]; out[3 * k + 2] = vc[v + 2];
    }
    color.needsUpdate = true;
  }

  // Frames the solid from the iso direction, and puts the ground grid
  // under it (the orbit stays above that plane).
  resetCamera() {
    if (!this.geometry || !this.geometry.boundingSphere) return;
    this.geometry.computeBoundingBox();
    const box = this.geometry.boundingBox;
    const r = Math.max(this.geometry.boundingSphere.radius, 1e-3);
    this.groundZ = box.min.z;
    if (this.grid) this.scene.remove(this.grid);
    const c = this.geometry.boundingSphere.center;
    this.grid = new THREE.GridHelper(r * 6, 12, 0x3a4150, 0x2c323c);
    this.grid.rotation.x = Math.PI / 2;  // the xy plane, under the solid
    this.grid.position.set(c.x, c.y, box.min.z - 1e-3 * r);
    this.scene.add(this.grid);
    this.look('iso');
  }

  // A view preset (camera.js PRESETS: front, side, top, iso), or 'frame':
  // the solid framed from where the camera looks now.
  look(preset) {
    if (!this.geometry || !this.geometry.boundingSphere) return false;
    const s = this.geometry.boundingSphere;
    let dir = PRESETS[preset];
    if (!dir) {
      const d = new THREE.Vector3().subVectors(this.camera.position,
        this.controls ? this.controls.target : s.center).normalize();
      dir = { x: d.x, y: d.y, z: d.z };
    }
    const f = frameSphere(s.center, s.radius, dir, this.camera.fov, this.camera.aspect);
    this.camera.position.set(f.eye.x, f.eye.y, f.eye.z);
    this.camera.near = f.distance / 100;
    this.camera.far = f.distance * 100;
    this.camera.updateProjectionMatrix();
    if (this.controls) {
      this.controls.target.set(f.target.x, f.target.y, f.target.z);
      this.controls.update();
    } else {
      this.camera.lookAt(s.center);
    }
    this.needsRender = true;
    return true;
  }

  // The ray under a pointer at client coordinates: {origin, direction}.
  ray(clientX, clientY) {
    this.camera.updateMatrixWorld();  // the camera may have moved since the last draw
    const rect = this.canvas.getBoundingClientRect();
    const ndc = new THREE.Vector2(((clientX - rect.left) / rect.width) * 2 - 1,
      -((clientY - rect.top) / rect.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.camera);
    const { origin, direction } = this.raycaster.ray;
    return { origin: { x: origin.x, y: origin.y, z: origin.z },
      direction: { x: direction.x, y: direction.y, z: direction.z } };
  }

  // A local hit on the drawn surface (for the cursor and to decide whether a
  // press starts a tool): {point, normal} or null.
  localHit(clientX, clientY) {
    if (!this.mesh) return null;
    this.ray(clientX, clientY);
    const hits = this.raycaster.intersectObject(this.mesh, false);
    if (!hits.length) return null;
    const h = hits[0];
    const n = h.face ? h.face.normal : new THREE.Vector3(0, 0, 1);
    return { point: h.point.clone(), distance: h.distance, normal: { x: n.x, y: n.y, z: n.z } };
  }

  viewDirection() {
    const d = new THREE.Vector3();
    this.camera.getWorldDirection(d);
    return { x: d.x, y: d.y, z: d.z };
  }

  // Screen position (client px) of a world point.
  project(p) {
    this.camera.updateMatrixWorld();
    const v = new THREE.Vector3(p.x, p.y, p.z).project(this.camera);
    const rect = this.canvas.getBoundingClientRect();
    return { x: rect.left + ((v.x + 1) / 2) * rect.width, y: rect.top + ((1 - v.y) / 2) * rect.height };
  }

  // The brush disc at a local hit ({point, normal}) with the brush's
  // radius; null hides it.
  showCursor(hit, radius) {
    this.needsRender = true;
    if (!hit) {
      this.cursor.hide();
      return;
    }
    // The centre dot: about 8 pixels across at the hit's distance.
    const h = this.canvas.clientHeight || 600;
    const perPixel = (2 * (hit.distance || 1) * Math.tan((this.camera.fov * Math.PI) / 360)) / h;
    this.cursor.place(hit.point, hit.normal || { x: 0, y: 0, z: 1 }, radius, 4 * perPixel);
  }

  // The control mesh overlay from Inspect: control_mesh (edges) and
  // control_positions (current positions).
  setControlMesh(mesh, positions, visible) {
    this.needsRender = true;
    if (this.controlLines) {
      this.overlay.remove(this.controlLines);
      this.controlGeometry.dispose();
      this.controlLines = null;
    }
    if (!visible || !mesh || !positions) return;
    const ev = mesh.edge_vertices || [];
    const sharp = mesh.edge_sharp || [];
    const arr = new Float32Array(ev.length * 3);
    const col = new Float32Array(ev.length * 3);
    for (let i = 0; i < ev.length; ++i) {
      for (let a = 0; a < 3; ++a) arr[3 * i + a] = positions[3 * ev[i] + a];
      const s = sharp[i >> 1];
      col[3 * i] = s ? 1.0 : 0.45; col[3 * i + 1] = s ? 0.35 : 0.85; col[3 * i + 2] = s ? 0.3 : 1.0;
    }
    // Drawn twice: edges in front of the surface solid (depth-tested),
    // edges behind it faint (seen through), so front and back never tangle.
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(arr, 3));
    g.setAttribute('color', new THREE.BufferAttribute(col, 3));
    const front = new THREE.LineSegments(g, new THREE.LineBasicMaterial({ vertexColors: true }));
    front.renderOrder = 2;
    const behind = new THREE.LineSegments(g, new THREE.LineBasicMaterial({
      vertexColors: true, depthTest: false, depthWrite: false, transparent: true, opacity: 0.16 }));
    behind.renderOrder = 1;
    this.controlLines = new THREE.Group();
    this.controlLines.add(front, behind);
    this.controlGeometry = g;
    this.overlay.add(this.controlLines);
  }

  // Control faces to highlight (hover.js): [{points: [{x, y, z}, ...],
  // kind: 'ok' | 'refused' | 'chosen'}], filled and outlined over the
  // surface; [] clears.
  showFaces(faces) {
    this.needsRender = true;
    for (const c of [...this.faceGroup.children]) {
      this.faceGroup.remove(c);
      c.geometry.dispose();
    }
    for (const { points, kind } of faces) {
      if (!points || points.length < 3) continue;
      const v = [];
      for (let i = 1; i + 1 < points.length; ++i) {
        for (const p of [points[0], points[i], points[i + 1]]) v.push(p.x, p.y, p.z);
      }
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(v), 3));
      const fill = new THREE.Mesh(g, (this.faceMaterials[kind] || this.faceMaterials.ok).fill);
      fill.renderOrder = 3;
      const outline = new THREE.LineLoop(new THREE.BufferGeometry().setFromPoints(
        points.map((p) => new THREE.Vector3(p.x, p.y, p.z))), (this.faceMaterials[kind] || this.faceMaterials.ok).line);
      outline.renderOrder = 3;
      this.faceGroup.add(fill, outline);
    }
  }

  // Pins and loads from Inspect (loads = true), and this page's curve in
  // progress.
  setMarkers({ loads = [], constraints = [], curvePoints = [] }, scale) {
    this.needsRender = true;
    for (const c of [...this.markers.children]) {
      this.markers.remove(c);
      c.traverse((o) => { if (o.geometry) o.geometry.dispose(); });
    }
    const r = scale * 0.02;
    const v3 = (p) => new THREE.Vector3(p.x || 0, p.y || 0, p.z || 0);
    const region = (reg, color) => {
      if (!reg) return;
      const m = new THREE.MeshBasicMaterial({ color, transparent: true, opacity: 0.25, depthWrite: false });
      if (reg.sphere) {
        const o = new THREE.Mesh(new THREE.SphereGeometry(reg.sphere.radius, 20, 10), m);
        o.position.copy(v3(reg.sphere.center));
        this.markers.add(o);
      } else if (reg.box) {
        const a = v3(reg.box.min);
        const b = v3(reg.box.max);
        const o = new THREE.Mesh(new THREE.BoxGeometry(b.x - a.x, b.y - a.y, b.z - a.z), m);
        o.position.copy(a.clone().add(b).multiplyScalar(0.5));
        this.markers.add(o);
      }
    };
    const dot = (p, color, size = r) => {
      const o = new THREE.Mesh(new THREE.SphereGeometry(size, 12, 6), new THREE.MeshBasicMaterial({ color }));
      o.position.copy(v3(p));
      this.markers.add(o);
    };
    const line = (pts, color) => {
      const g = new THREE.BufferGeometry().setFromPoints(pts.map(v3));
      const o = new THREE.Line(g, new THREE.LineBasicMaterial({ color, depthTest: false }));
      o.renderOrder = 3;
      this.markers.add(o);
    };
    for (const c of constraints) region(c.region, 0x4aa3ff);
    for (const l of loads) {
      const at = l.position || l.material_point;
      switch (l.kind) {
        case 'point_force': {
          const f = v3(l.force || {});
          const len = f.length();
          if (at && len > 0) {
            this.markers.add(new THREE.ArrowHelper(f.clone().normalize(), v3(at), scale * 0.3, 0xff7050));
          }
          break;
        }
        case 'pressure':
          region(l.region, (l.pressure || 0) > 0 ? 0xff5040 : 0x40a0ff);
          break;
        case 'drag':
          if (at && l.target) {
            line([at, l.target], 0xffd040);
            dot(l.target, 0xffd040);
          }
          break;
        case 'curve':
          if (l.targets && l.targets.length) line(l.targets, 0x60ff90);
          if (l.positions && l.positions.length) line(l.positions, 0x2f9a55);
          break;
        default:
          if (at) dot(at, 0xffffff);
      }
    }
    if (curvePoints.length) {
      for (const p of curvePoints) dot(p, 0x60ff90, r * 1.2);
      if (curvePoints.length > 1) line(curvePoints, 0x60ff90);
    }
  }

  // The cut-away (cutaway.js): the surface clipped on the plane's normal
  // side, and the section's triangles (positions, 9 per triangle; colours,
  // 3 per vertex) drawn on the plane. null: none.
  setSection(section) {
    this.needsRender = true;
    if (this.sectionMesh) {
      this.scene.remove(this.sectionMesh);
      this.sectionMesh.geometry.dispose();
      this.sectionMesh = null;
    }
    if (!section) {
      this.surfaceMaterial.clippingPlanes = [];
      this.surfaceMaterial.needsUpdate = true;
      return;
    }
    this.renderer.localClippingEnabled = true;
    const n = new THREE.Vector3(section.plane.normal.x, section.plane.normal.y, section.plane.normal.z).normalize();
    const p = new THREE.Vector3(section.plane.point.x, section.plane.point.y, section.plane.point.z);
    // Kept: n . x <= n . p (three.js keeps a plane's positive side).
    this.surfaceMaterial.clippingPlanes = [new THREE.Plane(n.clone().negate(), n.dot(p))];
    this.surfaceMaterial.needsUpdate = true;
    if (section.positions.length === 0) return;
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(section.positions, 3));
    g.setAttribute('color', new THREE.BufferAttribute(section.colors, 3));
    if (!this.sectionMaterial) {
      this.sectionMaterial = new THREE.MeshBasicMaterial({ vertexColors: true, side: THREE.DoubleSide });
    }
    this.sectionMesh = new THREE.Mesh(g, this.sectionMaterial);
    this.scene.add(this.sectionMesh);
  }

  // Draws if anything changed; returns whether it drew.
  render(force = false) {
    if (!this.needsRender && !force) return false;
    this.needsRender = false;
    this.renderer.render(this.scene, this.camera);
    return true;
  }
}
