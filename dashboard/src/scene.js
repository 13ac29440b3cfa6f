// The 3D view: a body, strands (particles inside the body and segments through it in red), orbit/zoom/pan, drawn on demand.
import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";

export const INSIDE_RGB = [230, 20, 20];
export const LAYER_RGB = { result: [112, 74, 38], source: [70, 110, 170], compare: [40, 150, 90] };
const BODY_COLOR = 0xd9c7b8;
/** The wrapped body's wireframe over the target: a colour apart from skin and both strand layers. */
export const WRAP_COLOR = 0x2060d0;
const WRAP_OPACITY = 0.45;
const SRGB_TO_LINEAR = Float32Array.from({ length: 256 }, (_, value) => {
  const c = value / 255;  // the sRGB transfer function, inverted
  return c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4;
});

function bodyGeometry(arrays) {
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute("position", new THREE.BufferAttribute(arrays.vertices, 3));
  geometry.setIndex(new THREE.BufferAttribute(arrays.faces, 1));
  geometry.computeVertexNormals();
  geometry.computeBoundingBox();
  geometry.computeBoundingSphere();
  return geometry;
}

/** A body's three.js mesh from a display payload (vertices, faces). Its depth is pushed back a little (polygon
 * offset), so a wireframe lying on its surface (the wrapped body, within a millimetre of it) is drawn over it
 * rather than flickering in and out; lines and strands do not take polygon offset, so they keep their place. */
export function bodyMesh({ arrays }, color = BODY_COLOR) {
  return new THREE.Mesh(bodyGeometry(arrays), new THREE.MeshStandardMaterial({ color, roughness: 0.8,
    side: THREE.DoubleSide, polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 2 }));
}

/** The wrapped body (the source's mesh in the target's shape) as a translucent wireframe to lay over the target:
 * where its edges vanish it lies under the target's surface. */
export function wrapOverlay({ arrays }) {
  return new THREE.Mesh(bodyGeometry(arrays), new THREE.MeshBasicMaterial({
    color: WRAP_COLOR, wireframe: true, transparent: true, opacity: WRAP_OPACITY, depthWrite: false }));
}

/** Strands' line segments from a display payload: file colours when present, else the layer's; particles inside
 * the body and segments passing through it (between two particles outside) in red. Those segments are drawn on top
 * of everything (no depth test): the body would hide them otherwise, and they are what the viewer is asked to
 * show. */
export function strandLines({ arrays }, rgb, showInside = true) {
  const positions = arrays.positions;
  const starts = arrays.starts;
  const vertices = positions.length / 3;
  const strands = starts.length - 1;
  const inside = showInside ? arrays.inside : null;
  const crossing = showInside ? arrays.crossing : null;
  const flagged = inside || crossing;
  const outerIndex = new Uint32Array(2 * (vertices - strands));
  const insideIndex = new Uint32Array(flagged ? 2 * (vertices - strands) : 0);
  let outer = 0;
  let within = 0;
  for (let strand = 0; strand < strands; strand++) {
    for (let vertex = starts[strand]; vertex < starts[strand + 1] - 1; vertex++) {
      if (inside?.[vertex] || inside?.[vertex + 1] || crossing?.[vertex]) {
        insideIndex[within++] = vertex;
        insideIndex[within++] = vertex + 1;
      } else {
        outerIndex[outer++] = vertex;
        outerIndex[outer++] = vertex + 1;
      }
    }
  }
  // colours are sRGB (files, the layer colours); the renderer works in linear light
  // a crossing segment's two vertices are red (a strand's last vertex starts none: crossing[vertex - 1] at a
  // strand's first vertex is the previous strand's last, 0)
  const red = (vertex) => inside?.[vertex] || crossing?.[vertex] || (vertex > 0 && crossing?.[vertex - 1]);
  const rgbOf = (vertex) => (red(vertex) ? INSIDE_RGB
    : arrays.color ? arrays.color.subarray(3 * vertex, 3 * vertex + 3) : rgb);
  const colors = new Float32Array(vertices * 3);
  for (let vertex = 0; vertex < vertices; vertex++) {
    const source = rgbOf(vertex);
    for (let channel = 0; channel < 3; channel++) colors[3 * vertex + channel] = SRGB_TO_LINEAR[source[channel]];
  }
  const positionAttribute = new THREE.BufferAttribute(positions, 3);
  const colorAttribute = new THREE.BufferAttribute(colors, 3);
  const lines = (index, onTop) => {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", positionAttribute);
    geometry.setAttribute("color", colorAttribute);
    geometry.setIndex(new THREE.BufferAttribute(index, 1));
    geometry.computeBoundingSphere();
    const segments = new THREE.LineSegments(geometry,
      new THREE.LineBasicMaterial({ vertexColors: true, depthTest: !onTop }));
    if (onTop) segments.renderOrder = 1;
    return segments;
  };
  const group = new THREE.Group();
  group.add(lines(outerIndex.subarray(0, outer), false));
  if (within) group.add(lines(insideIndex.subarray(0, within), true));
  return group;
}

let software = null;
/** Whether WebGL here is a software renderer (SwiftShader, llvmpipe: no GPU). There antialiasing doubles the frame
 * time (bench/dashboard.py), so the viewer draws without it. */
export function softwareWebGL() {
  if (software === null) {
    const gl = document.createElement("canvas").getContext("webgl2");
    const info = gl?.getExtension("WEBGL_debug_renderer_info");
    const renderer = info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : "";
    software = /swiftshader|llvmpipe|software/i.test(renderer);
    gl?.getExtension("WEBGL_lose_context")?.loseContext();
  }
  return software;
}

/** One canvas: the scene, a camera with orbit controls, lights; redrawn when something changes. */
export class Viewer {
  constructor(container) {
    this.container = container;
    this.software = softwareWebGL();
    this.renderer = new THREE.WebGLRenderer({ antialias: !this.software, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    this.renderer.setClearColor(0xffffff);
    container.append(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(35, 1, 0.001, 100);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8a8a, 2.2));
    const light = new THREE.DirectionalLight(0xffffff, 1.5);
    light.position.set(1, 2, 3);
    this.scene.add(light);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener("change", () => this.draw());
    this.groups = new Map();
    this.resizer = new ResizeObserver(() => this.resize());
    this.resizer.observe(container);
    this.resize();
  }

  resize() {
    const { clientWidth: width, clientHeight: height } = this.container;
    if (!width || !height) return;
    this.renderer.setSize(width, height, false);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
    this.draw();
  }

  /** Put `object` under the name `name` (replacing what was there), shifted by `offset` metres along x. */
  set(name, object, offset = 0) {
    this.clear(name);
    if (!object) return;
    const group = new THREE.Group();
    group.position.x = offset;
    group.add(object);
    this.groups.set(name, group);
    this.scene.add(group);
    this.draw();
  }

  clear(name) {
    const group = this.groups.get(name);
    if (!group) return;
    this.scene.remove(group);
    group.traverse((child) => {
      child.geometry?.dispose();
      child.material?.dispose();
    });
    this.groups.delete(name);
  }

  visible(name, shown) {
    const group = this.groups.get(name);
    if (group) group.visible = shown;
    this.draw();
  }

  /** Aim the camera at `box` (a THREE.Box3) from the front (+Z), slightly above. */
  frame(box) {
    const centre = box.getCenter(new THREE.Vector3());
    const size = box.getSize(new THREE.Vector3()).length();
    this.controls.target.copy(centre);
    this.camera.position.set(centre.x, centre.y + 0.15 * size, centre.z + 1.3 * size);
    this.camera.near = size / 1000;
    this.camera.far = size * 20;
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.draw();
  }

  /** The box around what `names` hold (all when omitted). */
  box(names) {
    const box = new THREE.Box3();
    for (const [name, group] of this.groups) if (!names || names.includes(name)) box.expandByObject(group);
    return box;
  }

  draw() {
    if (this.pending) return;
    this.pending = requestAnimationFrame(() => {
      this.pending = null;
      this.renderer.render(this.scene, this.camera);
    });
  }

  /** Milliseconds per frame over `frames` frames drawn back to back, each waited for (a pixel read blocks until
   * the GPU, here software WebGL, has finished it), the camera turning a little each frame. */
  measureFrames(frames) {
    const gl = this.renderer.getContext();
    const pixel = new Uint8Array(4);
    const times = [];
    for (let frame = 0; frame < frames; frame++) {
      this.controls.object.position.applyAxisAngle(new THREE.Vector3(0, 1, 0), 0.01);
      this.camera.lookAt(this.controls.target);
      const began = performance.now();
      this.renderer.render(this.scene, this.camera);
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);
      times.push(performance.now() - began);
    }
    return times;
  }

  dispose() {
    this.resizer.disconnect();
    for (const name of [...this.groups.keys()]) this.clear(name);
    this.controls.dispose();
    this.renderer.dispose();
    this.renderer.forceContextLoss();
    this.renderer.domElement.remove();
  }
}

/** A picture of a body for a list: drawn once by a shared offscreen renderer, returned as a data URL. */
let thumbnailRenderer = null;
export function thumbnail(payload, size = 96) {
  thumbnailRenderer ??= new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  thumbnailRenderer.setSize(size, size, false);
  thumbnailRenderer.setClearColor(0xf2f4f7);
  const scene = new THREE.Scene();
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8a8a, 2.2));
  const mesh = bodyMesh(payload);
  // turn the body's up (header) to +Y
  mesh.quaternion.setFromUnitVectors(new THREE.Vector3(...payload.header.up), new THREE.Vector3(0, 1, 0));
  scene.add(mesh);
  const box = new THREE.Box3().setFromObject(mesh);
  const centre = box.getCenter(new THREE.Vector3());
  const height = box.getSize(new THREE.Vector3()).length();
  const camera = new THREE.PerspectiveCamera(30, 1, height / 1000, height * 10);
  const light = new THREE.DirectionalLight(0xffffff, 1.5);
  light.position.set(centre.x + height, centre.y + height, centre.z + 2 * height);
  scene.add(light);
  camera.position.set(centre.x + 0.6 * height, centre.y + 0.2 * height, centre.z + 1.6 * height);
  camera.lookAt(centre);
  thumbnailRenderer.render(scene, camera);
  mesh.geometry.dispose();
  mesh.material.dispose();
  return thumbnailRenderer.domElement.toDataURL("image/png");
}

export { THREE };
