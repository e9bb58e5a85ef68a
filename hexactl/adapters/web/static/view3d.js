// The 3D view of the platform: base, commanded platform, legs coloured by stroke margin,
// measured platform (wireframe), goal ghost, work/tool frames and the pivot point.
// Rendering happens only when asked (a new record, an orbit, a resize).
import * as THREE from './vendor/three.module.js';
import { OrbitControls } from './vendor/OrbitControls.js';

const DEG = Math.PI / 180;

// ---------- pure kinematics helpers (also used without WebGL) ----------

/** R = Rz(yaw)·Ry(pitch)·Rx(roll), angles in degrees; row-major 3×3. */
export function rotation(rollDeg, pitchDeg, yawDeg) {
  const a = rollDeg * DEG, b = pitchDeg * DEG, c = yawDeg * DEG;
  const ca = Math.cos(a), sa = Math.sin(a), cb = Math.cos(b), sb = Math.sin(b), cc = Math.cos(c), sc = Math.sin(c);
  return [
    [cc * cb, cc * sb * sa - sc * ca, cc * sb * ca + sc * sa],
    [sc * cb, sc * sb * sa + cc * ca, sc * sb * ca - cc * sa],
    [-sb, cb * sa, cb * ca],
  ];
}

/** A point of the platform frame placed by an absolute pose [x,y,z,roll,pitch,yaw]: R·p + t. */
export function transformPoint(pose, p) {
  const R = rotation(pose[3], pose[4], pose[5]);
  return [
    R[0][0] * p[0] + R[0][1] * p[1] + R[0][2] * p[2] + pose[0],
    R[1][0] * p[0] + R[1][1] * p[1] + R[1][2] * p[2] + pose[1],
    R[2][0] * p[0] + R[2][1] * p[1] + R[2][2] * p[2] + pose[2],
  ];
}

/** Absolute pose = home + relative pose, component-wise; null unless six finite numbers. */
export function absolutePose(home, rel) {
  if (!isPose(rel) || !isPose(home)) return null;
  return rel.map((v, i) => v + home[i]);
}

export function isPose(p) {
  return Array.isArray(p) && p.length === 6 && p.every((v) => typeof v === 'number' && Number.isFinite(v));
}

/** Stroke margin of a leg of the given joint-to-joint length, as a fraction of the stroke. */
export function strokeMargin(geometry, i, length) {
  const zero = geometry.zero_lengths?.[i] ?? 0;
  const scale = 1 + (geometry.sensor_scale_errors?.[i] ?? 0);
  const stroke = geometry.stroke;
  if (!Array.isArray(stroke) || stroke.length !== 2 || !(stroke[1] > stroke[0])) return null;
  const reading = (length - zero) / scale;
  return Math.min(reading - stroke[0], stroke[1] - reading) / (stroke[1] - stroke[0]);
}

export function marginColor(margin) {
  if (margin === null || !Number.isFinite(margin)) return 0x9aa7b8;
  if (margin > 0.2) return 0x3ecf6e;
  if (margin >= 0.05) return 0xf0b429;
  return 0xef4444;
}

function poseMatrix(pose) {
  const R = rotation(pose[3], pose[4], pose[5]);
  return new THREE.Matrix4().set(
    R[0][0], R[0][1], R[0][2], pose[0],
    R[1][0], R[1][1], R[1][2], pose[1],
    R[2][0], R[2][1], R[2][2], pose[2],
    0, 0, 0, 1);
}

/** Indices of points ordered by angle about their centroid in the xy plane. */
function polygonOrder(points) {
  const cx = points.reduce((s, p) => s + p[0], 0) / points.length;
  const cy = points.reduce((s, p) => s + p[1], 0) / points.length;
  return points.map((p, i) => [Math.atan2(p[1] - cy, p[0] - cx), i]).sort((a, b) => a[0] - b[0]).map((e) => e[1]);
}

function webgl2Available() {
  try {
    const canvas = document.createElement('canvas');
    const gl = canvas.getContext('webgl2');
    if (!gl) return false;
    const lose = gl.getExtension('WEBGL_lose_context');
    if (lose) lose.loseContext();
    return true;
  } catch (e) {
    return false;
  }
}

// ---------- scene pieces ----------

class Polygon {
  // A filled fan through n points (ordered by `order`) plus its outline.
  constructor(n, order, fillMaterial, lineMaterial) {
    this.n = n;
    this.order = order;
    this.positions = new Float32Array((n + 1) * 3);
    this.geometry = new THREE.BufferGeometry();
    this.geometry.setAttribute('position', new THREE.BufferAttribute(this.positions, 3));
    const index = [];
    for (let k = 0; k < n; k++) index.push(0, 1 + k, 1 + ((k + 1) % n));
    this.geometry.setIndex(index);
    this.group = new THREE.Group();
    if (fillMaterial) {
      this.mesh = new THREE.Mesh(this.geometry, fillMaterial);
      this.group.add(this.mesh);
    }
    this.linePositions = new Float32Array(n * 3);
    this.lineGeometry = new THREE.BufferGeometry();
    this.lineGeometry.setAttribute('position', new THREE.BufferAttribute(this.linePositions, 3));
    this.line = new THREE.LineLoop(this.lineGeometry, lineMaterial);
    this.group.add(this.line);
  }

  setPoints(points) {
    let cx = 0, cy = 0, cz = 0;
    for (const p of points) { cx += p.x; cy += p.y; cz += p.z; }
    const n = this.n;
    this.positions[0] = cx / n; this.positions[1] = cy / n; this.positions[2] = cz / n;
    this.order.forEach((idx, k) => {
      const p = points[idx];
      this.positions.set([p.x, p.y, p.z], 3 + 3 * k);
      this.linePositions.set([p.x, p.y, p.z], 3 * k);
    });
    this.geometry.attributes.position.needsUpdate = true;
    this.geometry.computeBoundingSphere();
    this.geometry.computeVertexNormals();
    this.lineGeometry.attributes.position.needsUpdate = true;
    this.lineGeometry.computeBoundingSphere();
  }
}

function makeTriad(length, opacity = 1) {
  const group = new THREE.Group();
  const head = length * 0.22;
  const colors = [0xef4444, 0x22c55e, 0x3b82f6];
  const dirs = [new THREE.Vector3(1, 0, 0), new THREE.Vector3(0, 1, 0), new THREE.Vector3(0, 0, 1)];
  dirs.forEach((d, i) => {
    const arrow = new THREE.ArrowHelper(d, new THREE.Vector3(), length, colors[i], head, head * 0.45);
    if (opacity < 1) {
      arrow.line.material.transparent = true; arrow.line.material.opacity = opacity;
      arrow.cone.material.transparent = true; arrow.cone.material.opacity = opacity;
    }
    group.add(arrow);
  });
  group.matrixAutoUpdate = false;
  return group;
}

// ---------- the view ----------

export class View3D {
  constructor(container) {
    this.container = container;
    this.labelsEl = container.querySelector('.labels');
    this.geometry = null;
    this.available = false;
    this.drawnBase = null;      // Vector3[6]: the base joints as drawn
    this.drawnPlatform = null;  // Vector3[6]: the commanded platform joints as drawn
    this.renderScheduled = false;
    this.framed = false;
    if (!webgl2Available()) {
      this.showError('3D view unavailable: this browser could not start WebGL 2 (hardware acceleration off or unsupported). ' +
        'Telemetry, plots and controls keep working.');
      return;
    }
    try {
      this.renderer = new THREE.WebGLRenderer({ antialias: true, alpha: false });
    } catch (e) {
      this.showError(`3D view unavailable: WebGL could not be started (${e && e.message ? e.message : e}). ` +
        'Telemetry, plots and controls keep working.');
      return;
    }
    this.available = true;
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.renderer.setClearColor(0x0a0e13, 1);
    container.prepend(this.renderer.domElement);
    this.renderer.domElement.addEventListener('webglcontextlost', (ev) => {
      ev.preventDefault();
      this.showError('3D view: the WebGL context was lost; reload the page to restore it.');
    });

    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 10, 100000);
    this.camera.up.set(0, 0, 1);
    this.camera.position.set(3800, -4600, 2900);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.target.set(0, 0, 900);
    this.controls.enableDamping = false;
    this.controls.addEventListener('change', () => this.requestRender());
    this.controls.update();

    this.scene.add(new THREE.HemisphereLight(0xdde8ff, 0x202830, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.8);
    sun.position.set(2000, -3000, 5000);
    this.scene.add(sun);

    this.world = new THREE.Group();
    this.scene.add(this.world);

    const resize = () => this.resize();
    new ResizeObserver(resize).observe(container);
    resize();
  }

  showError(text) {
    let el = this.container.querySelector('.view3d-error');
    if (!el) {
      el = document.createElement('div');
      el.className = 'view3d-error';
      this.container.appendChild(el);
    }
    el.textContent = text;
    if (this.renderer) this.renderer.domElement.style.visibility = 'hidden';
    const legend = this.container.querySelector('.legend');
    if (legend) legend.hidden = true;
  }

  resize() {
    if (!this.available) return;
    const w = Math.max(1, this.container.clientWidth), h = Math.max(1, this.container.clientHeight);
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }

  requestRender() {
    if (!this.available || this.renderScheduled) return;
    this.renderScheduled = true;
    requestAnimationFrame(() => { this.renderScheduled = false; this.render(); });
  }

  /** Build the static parts for a geometry (at connect, and when the calibration changes). */
  setGeometry(g) {
    this.geometry = normaliseGeometry(g);
    this.drawnBase = this.geometry ? this.geometry.base_joints.map((p) => new THREE.Vector3(p[0], p[1], p[2])) : null;
    this.drawnPlatform = null;
    if (!this.available) return;
    // dispose of the previous scene content
    this.world.traverse((o) => { if (o.geometry) o.geometry.dispose(); });
    this.scene.remove(this.world);
    this.world = new THREE.Group();
    this.scene.add(this.world);
    if (this.labelsEl) this.labelsEl.textContent = '';
    if (!this.geometry) { this.requestRender(); return; }
    const g2 = this.geometry;

    const size = Math.max(300, ...g2.base_joints.map((p) => Math.hypot(p[0], p[1])));
    this.size = size;
    const jointRadius = size * 0.022, legRadius = size * 0.011;

    // floor grid in the xy plane
    const grid = new THREE.GridHelper(size * 3.2, 16, 0x3a4656, 0x222b36);
    grid.rotation.x = Math.PI / 2;
    grid.position.z = Math.min(0, ...g2.base_joints.map((p) => p[2])) - 1;
    this.world.add(grid);
    const fixedTriad = makeTriad(size * 0.3);
    fixedTriad.matrix.identity();
    this.world.add(fixedTriad);

    // base
    const sphereGeo = new THREE.SphereGeometry(1, 20, 14);
    const baseMat = new THREE.MeshStandardMaterial({ color: 0x6b7a8f, metalness: 0.3, roughness: 0.6 });
    this.drawnBase.forEach((v) => {
      const s = new THREE.Mesh(sphereGeo, baseMat);
      s.scale.setScalar(jointRadius * 1.2);
      s.position.copy(v);
      this.world.add(s);
    });
    const baseOrder = polygonOrder(g2.base_joints);
    this.basePoly = new Polygon(6, baseOrder,
      new THREE.MeshStandardMaterial({ color: 0x3a4a5e, transparent: true, opacity: 0.35, side: THREE.DoubleSide, depthWrite: false }),
      new THREE.LineBasicMaterial({ color: 0x6b7a8f }));
    this.basePoly.setPoints(this.drawnBase);
    this.world.add(this.basePoly.group);

    // commanded platform
    const platOrder = polygonOrder(g2.platform_joints);
    this.platGroup = new THREE.Group();
    this.platPoly = new Polygon(6, platOrder,
      new THREE.MeshStandardMaterial({ color: 0x9aa7b8, transparent: true, opacity: 0.55, side: THREE.DoubleSide, metalness: 0.2, roughness: 0.5, depthWrite: false }),
      new THREE.LineBasicMaterial({ color: 0xdfe7f1 }));
    this.platGroup.add(this.platPoly.group);
    const platMat = new THREE.MeshStandardMaterial({ color: 0xc9d3df, metalness: 0.3, roughness: 0.5 });
    this.platSpheres = g2.platform_joints.map(() => {
      const s = new THREE.Mesh(sphereGeo, platMat);
      s.scale.setScalar(jointRadius);
      this.platGroup.add(s);
      return s;
    });
    this.world.add(this.platGroup);

    // legs
    const cylGeo = new THREE.CylinderGeometry(1, 1, 1, 14, 1);
    this.legs = g2.base_joints.map(() => {
      const m = new THREE.Mesh(cylGeo, new THREE.MeshStandardMaterial({ color: 0x3ecf6e, metalness: 0.25, roughness: 0.45 }));
      m.userData.radius = legRadius;
      this.world.add(m);
      return m;
    });
    this.legLabels = g2.base_joints.map((_, i) => {
      const el = document.createElement('div');
      el.className = 'leg-label';
      el.textContent = String(i + 1);
      this.labelsEl?.appendChild(el);
      return el;
    });

    // measured platform: wireframe outline and joints
    this.measPoly = new Polygon(6, platOrder, null, new THREE.LineBasicMaterial({ color: 0xe879f9 }));
    this.measPoints = new THREE.Points(new THREE.BufferGeometry().setAttribute('position', new THREE.BufferAttribute(new Float32Array(18), 3)),
      new THREE.PointsMaterial({ color: 0xe879f9, size: 7, sizeAttenuation: false }));
    this.measGroup = new THREE.Group();
    this.measGroup.add(this.measPoly.group, this.measPoints);
    this.measGroup.visible = false;
    this.world.add(this.measGroup);

    // goal ghost: translucent platform and thin legs
    this.ghostPoly = new Polygon(6, platOrder,
      new THREE.MeshBasicMaterial({ color: 0xffffff, transparent: true, opacity: 0.16, side: THREE.DoubleSide, depthWrite: false }),
      new THREE.LineBasicMaterial({ color: 0xffffff, transparent: true, opacity: 0.7 }));
    this.ghostLegPositions = new Float32Array(36);
    const ghostLegGeo = new THREE.BufferGeometry().setAttribute('position', new THREE.BufferAttribute(this.ghostLegPositions, 3));
    this.ghostLegs = new THREE.LineSegments(ghostLegGeo, new THREE.LineBasicMaterial({ color: 0xffffff, transparent: true, opacity: 0.35 }));
    this.ghostGroup = new THREE.Group();
    this.ghostGroup.add(this.ghostPoly.group, this.ghostLegs);
    this.ghostGroup.visible = false;
    this.world.add(this.ghostGroup);

    // frames
    this.workTriad = makeTriad(size * 0.2, 0.9);
    this.workTriad.visible = false;
    this.toolTriad = makeTriad(size * 0.2);
    this.toolTriad.visible = false;
    this.pivot = new THREE.Mesh(sphereGeo, new THREE.MeshBasicMaterial({ color: 0xfacc15 }));
    this.pivot.scale.setScalar(jointRadius * 0.8);
    this.pivot.visible = false;
    this.world.add(this.workTriad, this.toolTriad, this.pivot);

    if (!this.framed) {
      const hz = g2.home[2];
      const tz = hz * 0.55;
      this.controls.target.set(0, 0, tz);
      const d = Math.max(size * 3.0, hz * 2.6);
      this.camera.position.set(d * 0.58, -d * 0.72, tz + d * 0.45);
      this.controls.update();
      this.framed = true;
    }
    this.requestRender();
  }

  /**
   * Place everything for a record (and the goal ghost, a relative pose or null).
   * Computes the drawn joint vectors even without WebGL, so legLengths() always
   * reports what is (or would be) drawn.
   */
  update(record, ghostGoal) {
    const g = this.geometry;
    if (!g || !record) return;
    const abs = absolutePose(g.home, record.pose_command);
    if (!abs) return;
    const plat = g.platform_joints.map((p) => { const q = transformPoint(abs, p); return new THREE.Vector3(q[0], q[1], q[2]); });
    this.drawnPlatform = plat;
    const locked = Number.isInteger(record.locked_leg) ? record.locked_leg - 1 : -1;
    this.margins = plat.map((p, i) => strokeMargin(g, i, p.distanceTo(this.drawnBase[i])));
    if (!this.available) return;

    this.platPoly.setPoints(plat);
    plat.forEach((p, i) => this.platSpheres[i].position.copy(p));

    const yAxis = new THREE.Vector3(0, 1, 0);
    plat.forEach((p, i) => {
      const b = this.drawnBase[i];
      const leg = this.legs[i];
      const dir = new THREE.Vector3().subVectors(p, b);
      const len = dir.length();
      leg.position.copy(b).addScaledVector(dir, 0.5);
      if (len > 0) leg.quaternion.setFromUnitVectors(yAxis, dir.clone().divideScalar(len));
      const r = leg.userData.radius * (i === locked ? 1.5 : 1);
      leg.scale.set(r, len, r);
      leg.material.color.setHex(i === locked ? 0x3b82f6 : marginColor(this.margins[i]));
      leg.material.emissive.setHex(i === locked ? 0x1d3f8f : 0x000000);
      const label = this.legLabels[i];
      const m = this.margins[i];
      label.textContent = i === locked ? `${i + 1} locked` : `${i + 1}${m !== null && m < 0.2 ? ` ${(m * 100).toFixed(0)}%` : ''}`;
      label.classList.toggle('locked', i === locked);
    });

    // measured platform
    const measAbs = absolutePose(g.home, record.pose_measured);
    if (measAbs) {
      const mp = g.platform_joints.map((p) => { const q = transformPoint(measAbs, p); return new THREE.Vector3(q[0], q[1], q[2]); });
      this.measPoly.setPoints(mp);
      const attr = this.measPoints.geometry.attributes.position;
      mp.forEach((p, i) => attr.setXYZ(i, p.x, p.y, p.z));
      attr.needsUpdate = true;
      this.measPoints.geometry.computeBoundingSphere();
      this.measGroup.visible = true;
    } else {
      this.measGroup.visible = false;
    }

    // goal ghost
    const ghostAbs = absolutePose(g.home, ghostGoal);
    if (ghostAbs) {
      const gp = g.platform_joints.map((p) => { const q = transformPoint(ghostAbs, p); return new THREE.Vector3(q[0], q[1], q[2]); });
      this.ghostPoly.setPoints(gp);
      gp.forEach((p, i) => {
        const b = this.drawnBase[i];
        this.ghostLegPositions.set([b.x, b.y, b.z, p.x, p.y, p.z], 6 * i);
      });
      this.ghostLegs.geometry.attributes.position.needsUpdate = true;
      this.ghostLegs.geometry.computeBoundingSphere();
      this.ghostGroup.visible = true;
    } else {
      this.ghostGroup.visible = false;
    }

    // work frame (home + work), tool frame (on the commanded platform) and pivot point
    const frames = record.frames && typeof record.frames === 'object' ? record.frames : null;
    const workAbs = frames ? absolutePose(g.home, frames.work) : null;
    if (workAbs) {
      this.workTriad.matrix.copy(poseMatrix(workAbs));
      this.workTriad.matrixWorldNeedsUpdate = true;
      this.workTriad.visible = true;
    } else {
      this.workTriad.visible = false;
    }
    if (frames && isPose(frames.tool)) {
      const m = poseMatrix(abs).multiply(poseMatrix(frames.tool));
      this.toolTriad.matrix.copy(m);
      this.toolTriad.matrixWorldNeedsUpdate = true;
      this.toolTriad.visible = true;
      this.pivot.position.setFromMatrixPosition(m);
      this.pivot.visible = true;
    } else {
      this.toolTriad.visible = false;
      this.pivot.visible = false;
    }
  }

  render() {
    if (!this.available) return;
    this.renderer.render(this.scene, this.camera);
    this.placeLabels();
  }

  placeLabels() {
    if (!this.legLabels || !this.drawnPlatform) {
      this.legLabels?.forEach((el) => { el.style.display = 'none'; });
      return;
    }
    const w = this.container.clientWidth, h = this.container.clientHeight;
    const v = new THREE.Vector3();
    this.legLabels.forEach((el, i) => {
      v.copy(this.drawnBase[i]).lerp(this.drawnPlatform[i], 0.55).project(this.camera);
      if (v.z > 1 || v.z < -1) { el.style.display = 'none'; return; }
      el.style.display = '';
      el.style.left = `${((v.x + 1) / 2) * w}px`;
      el.style.top = `${((1 - v.y) / 2) * h}px`;
    });
  }

  /** Joint-to-joint lengths (mm) of the legs as drawn, or null before a geometry and a record. */
  legLengths() {
    if (!this.drawnBase || !this.drawnPlatform) return null;
    return this.drawnPlatform.map((p, i) => p.distanceTo(this.drawnBase[i]));
  }
}

/** Check a geometry message's fields; null when it cannot be drawn. */
function normaliseGeometry(g) {
  if (!g || typeof g !== 'object') return null;
  const pts = (a) => Array.isArray(a) && a.length === 6 && a.every((p) => Array.isArray(p) && p.length === 3 && p.every(Number.isFinite));
  if (!pts(g.base_joints) || !pts(g.platform_joints) || !isPose(g.home)) return null;
  return {
    ...g,
    zero_lengths: Array.isArray(g.zero_lengths) ? g.zero_lengths : [0, 0, 0, 0, 0, 0],
    sensor_scale_errors: Array.isArray(g.sensor_scale_errors) ? g.sensor_scale_errors : [0, 0, 0, 0, 0, 0],
  };
}
