// The brush cursor: a disc lying on the surface at the point under the
// pointer, turned to the surface's normal, its rim at the brush radius (a
// filled disc, faint, hidden where the surface is in front of it; the rim
// and a centre dot drawn over everything so the radius always reads).

import * as THREE from 'three';

const COLOR = 0xffe070;
const SEGMENTS = 64;

export class BrushCursor {
  constructor() {
    this.group = new THREE.Group();
    this.group.visible = false;
    const disc = new THREE.Mesh(new THREE.CircleGeometry(1, SEGMENTS), new THREE.MeshBasicMaterial({
      color: COLOR, transparent: true, opacity: 0.18, depthWrite: false, side: THREE.DoubleSide,
      polygonOffset: true, polygonOffsetFactor: -2, polygonOffsetUnits: -4 }));
    disc.renderOrder = 4;
    // The rim: a band (WebGL lines are one pixel wide) drawn over
    // everything, with a dark edge outside it for light surfaces.
    const ring = new THREE.Mesh(new THREE.RingGeometry(0.95, 1, SEGMENTS), new THREE.MeshBasicMaterial({
      color: COLOR, depthTest: false, transparent: true, opacity: 0.95, side: THREE.DoubleSide }));
    ring.renderOrder = 5;
    const edge = new THREE.Mesh(new THREE.RingGeometry(1, 1.02, SEGMENTS), new THREE.MeshBasicMaterial({
      color: 0x2a2410, depthTest: false, transparent: true, opacity: 0.6, side: THREE.DoubleSide }));
    edge.renderOrder = 5;
    this.dot = new THREE.Mesh(new THREE.CircleGeometry(1, 16), new THREE.MeshBasicMaterial({
      color: COLOR, depthTest: false, side: THREE.DoubleSide }));
    this.dot.renderOrder = 5;
    this.group.add(disc, ring, edge, this.dot);
    this.z = new THREE.Vector3(0, 0, 1);
    this.normal = new THREE.Vector3();
  }

  // At `point` with unit `normal` ({x, y, z}), radius `radius` (m); the
  // centre dot `dot` metres across (a few pixels at the current zoom).
  place(point, normal, radius, dot) {
    const r = Math.max(radius, 1e-4);
    this.normal.set(normal.x, normal.y, normal.z).normalize();
    this.group.visible = true;
    this.group.quaternion.setFromUnitVectors(this.z, this.normal);
    this.group.position.set(point.x, point.y, point.z).addScaledVector(this.normal, r * 0.01);
    this.group.scale.setScalar(r);
    this.dot.scale.setScalar(Math.min(dot / r, 0.5));
  }

  hide() {
    this.group.visible = false;
  }

  get visible() {
    return this.group.visible;
  }
}
