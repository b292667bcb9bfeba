// meshflat demo: pick a sample or upload a mesh, choose a cone region, flatten, and see the
// 2D map (SVG from /v1/flatten) next to the 3D region textured through the returned UVs
// (GLB from /v1/flatten, loaded by three.js's GLTFLoader).
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

// Regions and frames that suit each bundled scan (its scalp, the cap at the neck).
// Lee Perry-Smith's box holds the shoulders: the cone starts inside the skull instead.
const PRESETS = {
  'fsaverage-head.ply': { axis: [0, 0, 1], angle: 70, apex: null, center: 'bbox_center', pole: [0, 0, -1], up: [0, 1, 0] },
  'lee-perry-smith.glb': { axis: [0, 1, 0], angle: 60, apex: [0, 1.2, -0.3], center: [0, 1.2, -0.3], pole: [0, -1, 0], up: [0, 0, 1] },
  'lee-perry-smith.obj': { axis: [0, 1, 0], angle: 60, apex: [0, 1.2, -0.3], center: [0, 1.2, -0.3], pole: [0, -1, 0], up: [0, 0, 1] },
  'nefertiti-lowres.obj': { axis: [0, 0, 1], angle: 60, apex: null, center: 'bbox_center', pole: [0, 0, -1], up: [0, 1, 0] },
};

const $ = (id) => document.getElementById(id);
const vector = (id) => $(id).value.split(',').map(Number);
// The API key, when the service requires one (MESHFLAT_API_KEYS); kept in the page only.
const keyHeaders = () => ($('apikey').value.trim() ? { 'X-API-Key': $('apikey').value.trim() } : {});

async function problemOf(response) {
  const problem = await response.json().catch(() => ({ detail: response.statusText }));
  return new Error(`${response.status}: ${problem.detail}`);
}

function setStatus(text, isError = false) {
  $('status').textContent = text;
  $('status').className = isError ? 'error' : '';
}

async function loadSamples() {
  const response = await fetch('/v1/samples', { headers: keyHeaders() });
  if (!response.ok) {
    setStatus(`${(await problemOf(response)).message}${response.status === 401 ? ' (enter the API key)' : ''}`, true);
    return;
  }
  const samples = await response.json();
  setStatus('');
  if ($('sample').options.length > 0) return; // listed already (the key was changed)
  for (const sample of samples) {
    const option = document.createElement('option');
    option.value = sample.name;
    option.textContent = `${sample.name} (${sample.faces.toLocaleString('en')} faces)`;
    $('sample').append(option);
  }
  $('credits').textContent = samples.map((s) => `${s.name}: ${s.credit}`).join(' · ');
  applyPreset();
}

function applyPreset() {
  const preset = PRESETS[$('sample').value];
  if (!preset) return;
  $('axis').value = preset.axis.join(', ');
  $('angle').value = preset.angle;
  $('apex').value = preset.apex ? preset.apex.join(', ') : '';
  $('center').value = Array.isArray(preset.center) ? preset.center.join(', ') : preset.center;
  $('pole').value = preset.pole.join(', ');
  $('up').value = preset.up.join(', ');
}

function params() {
  const center = $('center').value.trim();
  const cone = { axis: vector('axis'), half_angle_deg: Number($('angle').value) };
  if ($('apex').value.trim()) cone.apex = vector('apex');
  const p = { region: { cone }, layout: $('layout').value };
  if ($('auto').checked) {
    // Chosen by the service, and the map untangled: one piece, every triangle the right way.
    const rotation = $('up').value.trim() ? { pole: 'auto', up: vector('up') } : 'auto';
    Object.assign(p, { center: 'auto', rotation, sigma: 'auto', untangle: true });
  } else {
    p.center = /^[a-z_]+$/.test(center) ? center : center.split(',').map(Number);
    // Left blank, the pole and sigma are chosen by the service's default rule.
    if ($('pole').value.trim() && $('up').value.trim()) p.rotation = { pole: vector('pole'), up: vector('up') };
    if ($('sigma').value.trim()) p.sigma = Number($('sigma').value);
  }
  return p;
}

async function meshFile() {
  const upload = $('file').files[0];
  if (upload) return { blob: upload, name: upload.name };
  const name = $('sample').value;
  const response = await fetch(`/v1/samples/${encodeURIComponent(name)}`, { headers: keyHeaders() });
  if (!response.ok) throw await problemOf(response);
  return { blob: await response.blob(), name };
}

async function flattenAs(mesh, accept) {
  const form = new FormData();
  form.append('mesh', mesh.blob, mesh.name);
  form.append('params', JSON.stringify(params()));
  const headers = { Accept: accept, ...keyHeaders() };
  const response = await fetch('/v1/flatten', { method: 'POST', body: form, headers });
  if (!response.ok) throw await problemOf(response);
  return response;
}

// -- the 3D view ------------------------------------------------------------------------

const renderer = new THREE.WebGLRenderer({ canvas: $('view'), antialias: true, preserveDrawingBuffer: true });
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xf4f6f8);
scene.add(new THREE.HemisphereLight(0xffffff, 0x8899aa, 2.0));
const sun = new THREE.DirectionalLight(0xffffff, 1.5);
scene.add(sun);
const camera = new THREE.PerspectiveCamera(40, 1, 0.001, 1000);
const controls = new OrbitControls(camera, renderer.domElement);
let shown = null;

function resize() {
  const canvas = renderer.domElement;
  const { clientWidth: w, clientHeight: h } = canvas;
  renderer.setSize(w, h, false);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
}

function animate() {
  resize();
  controls.update();
  sun.position.copy(camera.position);
  renderer.render(scene, camera);
  requestAnimationFrame(animate);
}

function show(gltf) {
  if (shown) scene.remove(shown);
  shown = gltf.scene;
  scene.add(shown);
  const sphere = new THREE.Box3().setFromObject(shown).getBoundingSphere(new THREE.Sphere());
  controls.target.copy(sphere.center);
  camera.position.copy(sphere.center).add(new THREE.Vector3(0, 0.6, 1).normalize().multiplyScalar(sphere.radius * 3));
  camera.near = sphere.radius / 100;
  camera.far = sphere.radius * 100;
  camera.updateProjectionMatrix();
  let vertices = 0;
  shown.traverse((node) => {
    if (node.isMesh) vertices += node.geometry.attributes.position.count;
  });
  return vertices;
}

// -- the page -----------------------------------------------------------------------------

function clearPresets() {
  // A file of one's own: the sample's region and frame do not fit it; the service chooses.
  $('apex').value = '';
  $('center').value = 'bbox_center';
  for (const id of ['pole', 'up', 'sigma']) $(id).value = '';
}

function summary(extras) {
  const v = extras.validation;
  const m = v.margin_deg;
  const p = extras.params;
  const cap = p.sigma === null ? 'no warp' : `sigma ${p.sigma.toFixed(3)}`;
  const u = extras.untangle;
  const untangled = u ? [`untangled: ${u.moved_vertices} vertices moved, ${u.folded_after} folded after`] : [];
  return [
    `${v.seam_free ? 'seam-free' : 'NOT seam-free'}, ${v.star_shaped ? 'star-shaped' : 'NOT star-shaped'}`,
    `${p.method}, ${cap}, layout ${p.layout}`,
    `margins: seam ${m.seam.toFixed(1)}°, north ${m.north.toFixed(1)}°, south ${m.south.toFixed(1)}°`,
    `isometric energy ${extras.metrics.isometric.mean.toFixed(4)}`,
    `flagged faces: back-facing ${v.backfacing_faces}, folded ${v.folded_faces}, seam ${v.seam_faces}, singular ${v.singular_point_faces}`,
    ...untangled,
  ].join('\n');
}

async function flatten(event) {
  event?.preventDefault();
  $('go').disabled = true;
  document.body.dataset.state = 'flattening';
  setStatus('flattening…');
  const started = performance.now();
  try {
    const mesh = await meshFile();
    const [svgResponse, glbResponse] = await Promise.all([
      flattenAs(mesh, 'image/svg+xml'),
      flattenAs(mesh, 'model/gltf-binary'),
    ]);
    const svg = new DOMParser().parseFromString(await svgResponse.text(), 'image/svg+xml').documentElement;
    svg.removeAttribute('width');
    svg.removeAttribute('height');
    $('map').replaceChildren(document.importNode(svg, true));
    const gltf = await new GLTFLoader().parseAsync(await glbResponse.arrayBuffer(), '');
    const vertices = show(gltf);
    const extras = gltf.parser.json.asset.extras.meshflat;
    $('vertices').textContent = vertices.toLocaleString('en');
    $('summary').textContent = summary(extras);
    // The centre actually used (fitted, or the box centre the name stood for).
    $('center').value = extras.params.center.map((c) => Number(c.toPrecision(6))).join(', ');
    document.body.dataset.vertices = String(vertices);
    document.body.dataset.state = 'shown';
    setStatus(`done in ${Math.round(performance.now() - started)} ms`);
  } catch (error) {
    document.body.dataset.state = 'error';
    setStatus(error.message, true);
  } finally {
    $('go').disabled = false;
  }
}

$('sample').addEventListener('change', applyPreset);
$('file').addEventListener('change', clearPresets);
$('apikey').addEventListener('change', loadSamples);
$('auto').addEventListener('change', () => {
  for (const id of ['center', 'pole', 'sigma']) $(id).disabled = $('auto').checked;
});
$('form').addEventListener('submit', flatten);
animate();
loadSamples().then(() => {
  document.body.dataset.state = 'ready';
});
