// The 3D view: the watched surface (smooth shading, field colours), the
// control mesh overlay, pins and loads, the tool cursor; orbit, pan, zoom.
// Only drawing and local ray casts for the cursor: picking for commands is
// the server's Pick (material coordinates), geometry comes decoded from the
// Watch stream (surface.js).

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { colorize, fieldRange } from './colormap.js';

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
    this.scene.add(new THREE.HemisphereLight(0xdde6ff, 0x30302a, 1.2));
    const key = new THREE.DirectionalLight(0xffffff, 1.8);
    key.position.set(1, 1.5, 1);  // camera space: right, above, behind
    this.camera.add(key);
    this.scene.add(this.camera);

    // The boundary is closed and its quads face outward: front faces only.
    // A software renderer gets the cheaper Lambert shading (twice the frame
    // rate on SwiftShader, bench/reports/viewer).
    this.surfaceMaterial = this.software
      ? new THREE.MeshLambertMaterial({ color: 0xc9b8a0, side: THREE.FrontSide })
      : new THREE.MeshStandardMaterial({ color: 0xc9b8a0, roughness: 0.55, metalness: 0.05,
        side: THREE.FrontSide });
    this.mesh = null;
    this.geometry = null;
    this.overlay = new THREE.Group();
    this.scene.add(this.overlay);
    this.controlLines = null;
    this.markers = new THREE.Group();
    this.scene.add(this.markers);
    this.cursor = new THREE.Mesh(new THREE.SphereGeometry(1, 24, 12),
      new THREE.MeshBasicMaterial({ color: 0xffe070, wireframe: true, transparent: true, opacity: 0.5 }));
    this.cursor.visible = false;
    this.scene.add(this.cursor);
    this.grid = null;

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
    this.controls.addEventListener('change', () => { this.needsRender = true; });
    this.controls.mouseButtons = { LEFT: THREE.MOUSE.ROTATE, MIDDLE: THREE.MOUSE.PAN, RIGHT: THREE.MOUSE.PAN };
  }

  resize() {
    const w = this.container.clientWidth || 800;
    const h = this.container.clientHeight || 600;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.needsRender = true;
  }

  // Updates the surface from a SurfaceDecoder after a frame.
  updateSurface(decoder) {
    const n = decoder.vertexCount;
    // Several frames may have arrived since the last draw: rebuild on any
    // topology change among them, and copy every position.
    const topology = decoder.topologySerial !== this.topologySerial || !this.geometry ||
      this.geometry.getAttribute('position').count !== n;
    this.topologySerial = decoder.topologySerial;
    if (topology) {
      if (this.mesh) {
        this.scene.remove(this.mesh);
        this.geometry.dispose();
      }
      this.geometry = new THREE.BufferGeometry();
      this.geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3 * n), 3));
      this.geometry.setAttribute('color', new THREE.BufferAttribute(new Float32Array(3 * n), 3));
      const q = decoder.quads;
      const index = new Uint32Array((q.length / 4) * 6);
      for (let i = 0, j = 0; i < q.length; i += 4) {
        index[j++] = q[i]; index[j++] = q[i + 1]; index[j++] = q[i + 2];
        index[j++] = q[i]; index[j++] = q[i + 2]; index[j++] = q[i + 3];
      }
      this.geometry.setIndex(new THREE.BufferAttribute(index, 1));
      this.mesh = new THREE.Mesh(this.geometry, this.surfaceMaterial);
      this.scene.add(this.mesh);
    }
    const pos = this.geometry.getAttribute('position');
    const p = decoder.positions;
    const arr = pos.array;
    for (let i = 0; i < 3 * n; ++i) arr[i] = p[i];
    pos.needsUpdate = true;
    this.needsRender = true;
    this.geometry.computeVertexNormals();
    this.geometry.computeBoundingSphere();  // ray casts test it first
    this.updateColors(decoder);
    if (!this.framed && n > 0) {
      this.resetCamera();
      this.framed = true;
    }
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
      this.surfaceMaterial.color.set(useColors ? 0xffffff : 0xc9b8a0);
      this.surfaceMaterial.needsUpdate = true;
    }
    if (!useColors) {
      this.range = null;
      return;
    }
    this.range = fieldRange(this.field, values);
    const color = this.geometry.getAttribute('color');
    colorize(values, this.range, color.array);
    color.needsUpdate = true;
  }

  resetCamera() {
    if (!this.geometry || !this.geometry.boundingSphere) return;
    const s = this.geometry.boundingSphere;
    const c = s.center;
    const r = Math.max(s.radius, 1e-3);
    const d = r / Math.sin((this.camera.fov * Math.PI) / 360) * 1.15;
    const dir = new THREE.Vector3(0.62, -0.95, 0.55).normalize();
    this.camera.position.copy(c).addScaledVector(dir, d);
    this.camera.near = d / 100;
    this.camera.far = d * 100;
    this.camera.updateProjectionMatrix();
    this.needsRender = true;
    if (this.controls) {
      this.controls.target.copy(c);
      this.controls.update();
    } else {
      this.camera.lookAt(c);
    }
    if (this.grid) this.scene.remove(this.grid);
    this.geometry.computeBoundingBox();
    const box = this.geometry.boundingBox;
    this.grid = new THREE.GridHelper(r * 6, 12, 0x3a4150, 0x2c323c);
    this.grid.rotation.x = Math.PI / 2;  // the xy plane, under the solid
    this.grid.position.set(c.x, c.y, box.min.z - 1e-3 * r);
    this.scene.add(this.grid);
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
    return { point: h.point.clone(), distance: h.distance };
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

  showCursor(point, radius) {
    this.needsRender = true;
    if (!point) {
      this.cursor.visible = false;
      return;
    }
    this.cursor.visible = true;
    this.cursor.position.copy(point);
    this.cursor.scale.setScalar(Math.max(radius, 1e-4));
  }

  // The control mesh overlay from Inspect: control_mesh (edges) and
  // control_positions (current positions).
  setControlMesh(mesh, positions, visible) {
    this.needsRender = true;
    if (this.controlLines) {
      this.overlay.remove(this.controlLines);
      this.controlLines.geometry.dispose();
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
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(arr, 3));
    g.setAttribute('color', new THREE.BufferAttribute(col, 3));
    this.controlLines = new THREE.LineSegments(g, new THREE.LineBasicMaterial({
      vertexColors: true, depthTest: false, transparent: true, opacity: 0.8 }));
    this.controlLines.renderOrder = 2;
    this.overlay.add(this.controlLines);
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

  // Draws if anything changed; returns whether it drew.
  render(force = false) {
    if (!this.needsRender && !force) return false;
    this.needsRender = false;
    this.renderer.render(this.scene, this.camera);
    return true;
  }
}
