// meshflat demo: pick a sample or upload a mesh, choose a cone region, flatten, and see the
// 2D map (SVG from /v1/flatten) next to the 3D region textured through the returned UVs
// (GLB from /v1/flatten, loaded by three.js's GLTFLoader). A zone drawn on the map is
// measured by /v1/measure: its area, and its outline lifted onto the surface in the 3D view.
// Grafts placed by /v1/sites (in the zone, or over the region) show on the map and the head,
// with a table of each zone's area, density and grafts. Flows and whorls drawn on the map
// give the grafts their growth (params.growth): each shows as a short stroke on the map and
// the head. Grow hair grows a strand from each graft (/v1/strands, the length and exit angle
// given) and draws them on the head. Recipient and donor zones drawn on the map are weighed
// by /v1/plan: a table of each zone's area and grafts needed or available, the balance and
// the sessions. The units are the sample's (from /v1/samples), and what an answer warns of
// (units, a zone off the map) is listed. Every request goes through the typed client
// (clients/typescript), whose types come from the committed OpenAPI document.
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import { meshflat } from '../clients/typescript/index.ts';

// Regions and frames that suit each bundled scan (its scalp, the cap at the neck), and where
// its face looks (facing: the front at the top of the map; fsaverage is RAS, +Y anterior;
// Lee Perry-Smith looks along +Z). Lee Perry-Smith's box holds the shoulders: the cone
// starts inside the skull instead.
const PRESETS = {
  'fsaverage-head.ply': { axis: [0, 0, 1], angle: 70, apex: null, center: 'bbox_center', pole: [0, 0, -1], up: [0, 1, 0], facing: [0, 1, 0] },
  'lee-perry-smith.glb': { axis: [0, 1, 0], angle: 60, apex: [0, 1.2, -0.3], center: [0, 1.2, -0.3], pole: [0, -1, 0], up: [0, 0, 1], facing: [0, 0, 1] },
  'lee-perry-smith.obj': { axis: [0, 1, 0], angle: 60, apex: [0, 1.2, -0.3], center: [0, 1.2, -0.3], pole: [0, -1, 0], up: [0, 0, 1], facing: [0, 0, 1] },
  'nefertiti-lowres.obj': { axis: [0, 0, 1], angle: 60, apex: null, center: 'bbox_center', pole: [0, 0, -1], up: [0, 1, 0], facing: null },
};

// Each bundled scan's length unit, as /v1/samples gives it (estimated where its file has none).
const SAMPLE_UNITS = {};

// The page's elements by id (inputs, selects, outputs alike: the page knows which is which).
/** @type {(id: string) => any} */
const $ = (id) => document.getElementById(id);
const vector = (id) => $(id).value.split(',').map(Number);
// The API, with the key when the service requires one (MESHFLAT_API_KEYS; kept in the page
// only). A refusal is thrown with its field: the page marks the flow or whorl a 422 names.
const api = meshflat({ baseUrl: window.location.origin, apiKey: () => $('apikey').value });

function setStatus(text, isError = false) {
  $('status').textContent = text;
  $('status').className = isError ? 'error' : '';
}

async function loadSamples() {
  let samples;
  try {
    samples = await api.samples();
  } catch (error) {
    setStatus(`${error.message}${error.status === 401 ? ' (enter the API key)' : ''}`, true);
    return;
  }
  setStatus('');
  if ($('sample').querySelector('option:not(.upload)')) return; // listed already (the key was changed)
  for (const sample of samples) {
    const option = document.createElement('option');
    option.value = sample.name;
    option.textContent = `${sample.name} (${sample.faces.toLocaleString('en')} faces)`;
    $('sample').append(option);
    SAMPLE_UNITS[sample.name] = sample.units;
  }
  $('credits').textContent = samples.map((s) => `${s.name}: ${s.credit}`).join(' · ');
  if (!$('file').files[0]) applyPreset();
  else showUpload(); // a file chosen before the samples came: it stays the source
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
  $('facing').value = preset.facing ? preset.facing.join(', ') : '';
  if (SAMPLE_UNITS[$('sample').value]) $('units').value = SAMPLE_UNITS[$('sample').value];
  syncFrameFields();
}

// The fields the service fills in rather than reads are greyed: in automatic mode the centre,
// pole and sigma; with facing, the up direction (facing sets the roll). They still show the
// values the last answer used.
function syncFrameFields() {
  for (const id of ['center', 'pole', 'sigma']) $(id).disabled = $('auto').checked;
  $('up').disabled = Boolean($('facing').value.trim());
}

// What the last answer warns of: legal but probably wrong (units that make the region
// implausible, a zone off the map, more grafts than a scalp holds).
function showWarnings(answer) {
  const items = (answer?.warnings ?? []).map((w) => Object.assign(document.createElement('li'), { textContent: `${w.field}: ${w.message}` }));
  $('warnings').replaceChildren(...items);
  $('warnings').dataset.count = String(items.length);
}

function params() {
  const center = $('center').value.trim();
  const cone = { axis: vector('axis'), half_angle_deg: Number($('angle').value) };
  if ($('apex').value.trim()) cone.apex = vector('apex');
  // The faces painted in the file's vertex colours (all three vertices at the level), or the cone.
  const painted = { channel: $('channel').value, min: Number($('color-min').value) };
  const region = $('region-kind').value === 'vertex_color' ? { vertex_color: painted } : { cone };
  // The map and the 3D view coloured by the flags or by a distortion measure (with its bar).
  const p = { region, layout: $('layout').value, colour_by: $('colour-by').value };
  // Where the face looks: the map's front at its top (the landmarks name their own).
  const facing = $('facing').value.trim() ? vector('facing') : null;
  if ($('use-landmarks').checked) {
    // The head's frame: centre and rotation from the landmarks, sigma as given (or fitted).
    p.frame = { landmarks: { ...landmarks.points } };
    p.sigma = $('sigma').value.trim() ? Number($('sigma').value) : 'auto';
  } else if ($('auto').checked) {
    // Chosen by the service, and the map untangled: one piece, every triangle the right way.
    // With facing the roll is its; else the up direction's, when given.
    const rotation = !facing && $('up').value.trim() ? { pole: 'auto', up: vector('up') } : 'auto';
    Object.assign(p, { center: 'auto', rotation, sigma: 'auto', untangle: true });
    if (facing) p.facing = facing;
  } else {
    p.center = /^[a-z_]+$/.test(center) ? center : center.split(',').map(Number);
    // Left blank, the pole and sigma are chosen by the service's default rule. With facing,
    // it is the up direction too: the two must agree, and so they do exactly.
    const up = facing ?? ($('up').value.trim() ? vector('up') : null);
    if ($('pole').value.trim() && up) p.rotation = { pole: vector('pole'), up };
    if ($('sigma').value.trim()) p.sigma = Number($('sigma').value);
    if (facing) p.facing = facing;
  }
  return p;
}

// The samples' files, each downloaded once.
const sampleFiles = new Map();

// The mesh to flatten: the file uploaded, else the sample selected; `source` says which, so
// that a new flatten of the same mesh keeps what is drawn on its map.
async function meshFile() {
  const upload = $('file').files[0];
  if (upload) return { blob: upload, name: upload.name, source: upload };
  const name = $('sample').value;
  if (!sampleFiles.has(name)) sampleFiles.set(name, await api.sample(name));
  return { ...sampleFiles.get(name), source: `sample ${name}` };
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
    if (!node.isMesh) return;
    vertices += node.geometry.attributes.position.count;
    // Pushed back a little in depth, so that a zone's outline drawn on the surface shows.
    Object.assign(node.material, { polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1 });
    // Coloured by a measure (COLOR_0): the colours alone, without the checker.
    if (node.geometry.attributes.color) {
      node.material.map = null;
      node.material.needsUpdate = true;
    }
  });
  return vertices;
}

// -- a zone drawn on the map ----------------------------------------------------------------

const SVG = 'http://www.w3.org/2000/svg';
const ZONE_COLOUR = 0xe41a1c;
// The picture's plot box shows the layout's box padded by 4 % of its larger side
// (service/outputs/picture.py, _view), which the GLB's UVs scale to [0, 1]: 0.04 in u and v.
const PAD = 0.04;
// The map shown: its mesh, its params (with the frame the service resolved, so that
// /v1/measure draws the same map without choosing again) and the GLB's UV numbers.
let map = null;
// The outline drawn on the map, in the picture's pixels; ticket: the measuring that counts.
const zone = { points: [], drawing: false, closed: false, ticket: 0 };
let outline = null; // the lifted outline in the 3D view

const mapSvg = () => $('map').querySelector('svg');

// The plot box of the map picture, in SVG pixels, and the UVs' numbers.
function plotBox() {
  const plot = mapSvg().querySelector('#plot rect');
  const [left, top, width, height] = ['x', 'y', 'width', 'height'].map((a) => Number(plot.getAttribute(a)));
  const { scale, x_min: xMin, s_min: sMin, s_sign: sSign, max: [uMax, vMax] } = map.uv;
  return { left, top, width, height, scale, xMin, sMin, sSign, uSpan: uMax + 2 * PAD, vSpan: vMax + 2 * PAD };
}

// A point of the map picture (SVG pixels) in the layout's coordinates, through the UVs:
// x = u / scale + x_min, y = s_sign * (v / scale + s_min) (service/outputs/glb.py).
function toLayout([px, py]) {
  const b = plotBox();
  const u = -PAD + ((px - b.left) / b.width) * b.uSpan;
  const v = -PAD + ((py - b.top) / b.height) * b.vSpan;
  return [u / b.scale + b.xMin, b.sSign * (v / b.scale + b.sMin)];
}

// The inverse: a layout point to the picture's pixels.
function toPicture([x, y]) {
  const b = plotBox();
  const u = (x - b.xMin) * b.scale;
  const v = (b.sSign * y - b.sMin) * b.scale;
  return [b.left + ((u + PAD) / b.uSpan) * b.width, b.top + ((v + PAD) / b.vSpan) * b.height];
}

// An outline drawn on the map (the picture's pixels) as a zone's `outer`, in the layout's
// coordinates.
function layoutRing(points) {
  const ring = points.map(toLayout);
  return { x: ring.map((q) => q[0]), y: ring.map((q) => q[1]) };
}

// The crosshair while any drawing (the zone, a flow or whorl, a plan's zone) takes clicks.
function markDrawing() {
  $('map').classList.toggle('drawing', zone.drawing || growth.mode !== null || transplant.drawing !== null);
}

// A status line (the zone's, the grafts', the hair's): its text, shown as an error or not,
// and its state for the tests.
function showStatus(id, text, state) {
  $(id).textContent = text;
  $(id).className = state === 'error' ? 'error' : '';
  $(id).dataset.state = state;
}

function drawZone() {
  let group = mapSvg().querySelector('g.zone-drawing');
  if (!group) {
    group = document.createElementNS(SVG, 'g');
    group.setAttribute('class', 'zone-drawing');
    mapSvg().append(group);
  }
  const line = document.createElementNS(SVG, zone.closed ? 'polygon' : 'polyline');
  line.setAttribute('points', zone.points.map((p) => p.join(',')).join(' '));
  const dots = zone.points.map(([x, y]) => {
    const dot = document.createElementNS(SVG, 'circle');
    Object.entries({ cx: x, cy: y, r: 3 }).forEach(([name, value]) => dot.setAttribute(name, value));
    return dot;
  });
  group.replaceChildren(line, ...dots);
}

function removeOutline() {
  if (!outline) return;
  scene.remove(outline);
  outline.geometry.dispose();
  outline.material.dispose();
  outline = null;
}

function clearZone() {
  Object.assign(zone, { points: [], drawing: false, closed: false, ticket: zone.ticket + 1 });
  mapSvg()?.querySelector('g.zone-drawing')?.remove();
  markDrawing();
  removeOutline();
  showStatus('zone-area', '', 'none');
  delete $('zone-area').dataset.ring;
  delete $('zone-area').dataset.segments;
  clearSites();
}

// -- grafts placed by /v1/sites -------------------------------------------------------------

const SITES_COLOUR = 0x1b1b1b;
// A graft's stroke in the 3D view runs from its root (the site, dark) to its tip (hair
// brown): which way it grows shows without an arrowhead.
const STROKE_ROOT = new THREE.Color(SITES_COLOUR);
const STROKE_TIP = new THREE.Color(0x8c510a);
// A stroke's length: on the map in the picture's pixels; on the head a share of the region's
// size (its bounding sphere's radius), some 5 mm on an adult scalp in any unit.
const STROKE_PIXELS = 8;
const STROKE_OF_SIZE = 1 / 20;
let grafts = null; // the sites in the 3D view
let placed = null; // the params they were placed with
let sitesShown = null; // the answer shown
let strokes = null; // their growth directions in the 3D view
let sitesTicket = 0;

function dispose(object) {
  scene.remove(object);
  object.geometry.dispose();
  object.material.dispose();
}

function clearSites() {
  sitesTicket += 1;
  mapSvg()?.querySelector('g.sites-drawing')?.remove();
  if (grafts) dispose(grafts);
  if (strokes) dispose(strokes);
  grafts = null;
  strokes = null;
  $('sites-table').replaceChildren();
  showStatus('sites-status', '', 'none');
  delete $('sites-status').dataset.count;
  delete $('sites-status').dataset.strokes;
  showWarnings(null);
  placed = null;
  sitesShown = null;
  $('grow-hair').disabled = true;
  clearHair();
}

// Each site's map direction as a stroke from the site, in the picture's pixels: the layout's
// unit vector through the UVs' affine map (its y turned over by s_sign), at STROKE_PIXELS.
function mapStrokes(x, y, mapDirection) {
  const b = plotBox();
  const along = [(b.scale * b.width) / b.uSpan, (b.sSign * b.scale * b.height) / b.vSpan];
  return x.map((xi, i) => {
    const [px, py] = toPicture([xi, y[i]]);
    const [dx, dy] = mapDirection[i].map((c, k) => c * along[k]);
    const length = Math.hypot(dx, dy) || 1;
    const [sx, sy] = [(dx / length) * STROKE_PIXELS, (dy / length) * STROKE_PIXELS];
    return `M${px.toFixed(1)} ${py.toFixed(1)}l${sx.toFixed(1)} ${sy.toFixed(1)}`;
  });
}

// The growth on the head: a segment from each site along its direction, root to tip.
function showStrokes(position, direction) {
  const length = map.size * STROKE_OF_SIZE;
  const ends = position.flatMap((p, i) => [...p, ...p.map((c, k) => c + length * direction[i][k])]);
  const colours = position.flatMap(() => [...STROKE_ROOT.toArray(), ...STROKE_TIP.toArray()]);
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.Float32BufferAttribute(ends, 3));
  geometry.setAttribute('color', new THREE.Float32BufferAttribute(colours, 3));
  strokes = new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ vertexColors: true }));
  strokes.name = 'growth-strokes';
  scene.add(strokes);
  $('sites-status').dataset.strokes = String(geometry.attributes.position.count / 2);
}

function tableRow(cells, tag) {
  const row = document.createElement('tr');
  row.replaceChildren(...cells.map((text) => Object.assign(document.createElement(tag), { textContent: text })));
  return row;
}

// The grafts on the map: a dot at each, or with growth a stroke along its map direction.
function drawSitesOnMap(answer) {
  const { x, y, map_direction: mapDirection } = answer.sites;
  const grown = Boolean(answer.growth);
  mapSvg().querySelector('g.sites-drawing')?.remove();
  const group = document.createElementNS(SVG, 'g');
  group.setAttribute('class', 'sites-drawing');
  // With growth a stroke from each site along its direction; else a dot at each.
  const d = grown
    ? mapStrokes(x, y, mapDirection)
    : x.map((xi, i) => {
        const [px, py] = toPicture([xi, y[i]]);
        return `M${(px - 1).toFixed(1)} ${(py - 1).toFixed(1)}h2v2h-2Z`;
      });
  const path = document.createElementNS(SVG, 'path');
  path.setAttribute('d', d.join(''));
  if (grown) path.setAttribute('class', 'strokes');
  group.append(path);
  mapSvg().append(group);
  // The flows and whorls stay above the strokes, where they can be read.
  const drawn = mapSvg().querySelector('g.growth-drawing');
  if (drawn) mapSvg().append(drawn);
}

function showSites(answer) {
  const { position, direction } = answer.sites;
  const grown = Boolean(answer.growth);
  sitesShown = answer;
  drawSitesOnMap(answer);
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.Float32BufferAttribute(position.flat(), 3));
  grafts = new THREE.Points(geometry, new THREE.PointsMaterial({ color: SITES_COLOUR, size: 3, sizeAttenuation: false }));
  grafts.name = 'grafts';
  scene.add(grafts);
  if (grown) showStrokes(position, direction);
  // With growth, each zone's exit angle and its largest turn between neighbouring grafts
  // (null for fewer than two).
  const degrees = (value) => (value === null ? '–' : value.toFixed(1));
  const rows = answer.zones.map((z) => {
    const cells = [z.name, z.area_cm2.toFixed(2), z.density_per_cm2.toFixed(1), z.sites.toLocaleString('en')];
    if (grown) cells.push(degrees(z.exit_angle_deg), degrees(z.largest_turn_deg));
    return tableRow(cells, 'td');
  });
  const names = ['zone', 'area (cm²)', 'density (per cm²)', 'grafts'];
  if (grown) names.push('exit angle (°)', 'largest turn (°)');
  $('sites-table').replaceChildren(tableRow(names, 'th'), ...rows);
  // Fewer than two grafts have no distance apart (null).
  const apart = answer.min_distance_mm === null ? '' : `, at least ${answer.min_distance_mm.toFixed(2)} mm apart`;
  const angle = grown ? `, ${answer.growth.exit_angle_deg}° off the scalp` : '';
  showStatus('sites-status', `${answer.count.toLocaleString('en')} grafts${apart}${angle}`, 'placed');
  $('sites-status').dataset.count = String(answer.count);
}

// Grafts in the zone drawn (closed), else over the whole region, at the density asked.
async function placeSites() {
  clearSites();
  const ticket = sitesTicket;
  const density = Number($('density').value);
  const p = { ...map.params, units: $('units').value, density_per_cm2: density, seed: 1 };
  if (zone.closed) p.zones = [{ name: 'zone', outer: layoutRing(zone.points) }];
  const grows = growthParams();
  if (grows) p.growth = grows;
  growth.error = null;
  drawGrowth();
  showStatus('sites-status', 'placing…', 'placing');
  try {
    const answer = await api.json('/v1/sites', { mesh: map.mesh }, p);
    if (ticket !== sitesTicket) return;
    showWarnings(answer);
    showSites(answer);
    placed = p;
    $('grow-hair').disabled = false;
  } catch (error) {
    if (ticket !== sitesTicket) return;
    showStatus('sites-status', error.message, 'error');
    // A flow or whorl the service refused (params.growth.flow.1): marked on the map.
    const named = /^params\.growth\.(flow|whorls)\.(\d+)/.exec(error.field ?? '');
    growth.error = named ? { kind: named[1], index: Number(named[2]) } : null;
    drawGrowth();
  }
}

function startZone() {
  setGrowthMode(null);
  cancelPlanZone();
  clearZone();
  zone.drawing = true;
  markDrawing();
  showStatus('zone-area', 'Click points on the map; double-click to close the outline.', 'drawing');
}

// The outline lifted onto the surface, one segment per piece on it: none where it runs off
// the region (faces[i] null).
function showOutline({ points, faces }) {
  const ends = faces.flatMap((face, i) => (face === null ? [] : [...points[i], ...points[i + 1]]));
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.Float32BufferAttribute(ends, 3));
  outline = new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ color: ZONE_COLOUR }));
  outline.name = 'zone-outline';
  scene.add(outline);
  $('zone-area').dataset.segments = String(geometry.attributes.position.count / 2);
}

async function measure() {
  clearSites();
  const ticket = ++zone.ticket;
  const outer = layoutRing(zone.points);
  const p = { ...map.params, zones: [{ name: 'zone', outer }], units: $('units').value };
  $('zone-area').dataset.ring = JSON.stringify(outer);
  showStatus('zone-area', 'measuring…', 'measuring');
  try {
    const answer = await api.json('/v1/measure', { mesh: map.mesh }, p);
    const [measured] = answer.zones;
    if (ticket !== zone.ticket) return; // cleared, or measured again, meanwhile
    showWarnings(answer);
    removeOutline();
    showOutline(measured.outline[0]);
    showStatus('zone-area', `Zone: ${measured.area_cm2.toFixed(2)} cm²`, 'measured');
  } catch (error) {
    if (ticket === zone.ticket) showStatus('zone-area', error.message, 'error');
  }
}

// Where a click on the map is, in the picture's pixels.
function pictureAt(event) {
  const point = new DOMPoint(event.clientX, event.clientY).matrixTransform(mapSvg().getScreenCTM().inverse());
  return [point.x, point.y];
}

// A click adds a point (the second click of a double click adds none); a double click closes.
function addPoint(event) {
  if (!zone.drawing || event.detail > 1) return;
  zone.points.push(pictureAt(event));
  drawZone();
}

function closeZone() {
  if (!zone.drawing || zone.points.length < 3) return;
  Object.assign(zone, { drawing: false, closed: true });
  markDrawing();
  drawZone();
  measure();
}

// -- the hair's growth: flows and whorls drawn on the map ----------------------------------

// Flows (polylines along which the hair grows, first point to last) and whorls, in the
// picture's pixels as the zone is; the flow being drawn; the mode ('flow', 'whorl' or null);
// the item the last refusal named.
const growth = { flows: [], whorls: [], drawing: null, mode: null, error: null };

function svgElement(name, attributes) {
  const element = document.createElementNS(SVG, name);
  Object.entries(attributes).forEach(([key, value]) => element.setAttribute(key, value));
  return element;
}

const pointsText = (points) => points.map((p) => p.map((c) => c.toFixed(1)).join(',')).join(' ');

// A filled arrowhead at `to`, pointing away from `from`.
function arrowhead([fromX, fromY], [toX, toY], size = 12) {
  const length = Math.hypot(toX - fromX, toY - fromY) || 1;
  const [dx, dy] = [(toX - fromX) / length, (toY - fromY) / length];
  const back = [toX - size * dx, toY - size * dy];
  const side = [(-dy * size) / 2, (dx * size) / 2];
  return svgElement('polygon', { points: pointsText([[toX, toY], [back[0] + side[0], back[1] + side[1]], [back[0] - side[0], back[1] - side[1]]]) });
}

// A flow: its polyline, with an arrowhead where the hair grows to once ended, or its points
// while drawn.
function flowElement(points, ended) {
  const group = svgElement('g', { class: ended ? 'flow' : 'flow drawing' });
  group.append(svgElement('polyline', { points: pointsText(points) }));
  if (ended) group.append(arrowhead(points.at(-2), points.at(-1)));
  else group.append(...points.map(([cx, cy]) => svgElement('circle', { cx, cy, r: 3 })));
  return group;
}

// A whorl: its centre and three quarters of a circle round it, the arrow turning its way.
// The picture shows the scalp as seen from outside the head: a turn clockwise from outside
// is clockwise on it, whatever the layout and the file's winding (transforms/layouts.py,
// front_orientation, with the rows running down), so the arrow turns as the hair will.
// SVG's sweep flag 1 is clockwise on screen.
function whorlElement({ point: [cx, cy], turn }) {
  const radius = 12;
  const sense = turn === 'clockwise' ? 1 : -1;
  const end = (3 * Math.PI) / 2;
  const [ex, ey] = [cx + radius * Math.cos(sense * end), cy + radius * Math.sin(sense * end)];
  const arc = `M${cx + radius} ${cy}A${radius} ${radius} 0 1 ${sense > 0 ? 1 : 0} ${ex} ${ey}`;
  const tangent = [-Math.sin(sense * end) * sense, Math.cos(sense * end) * sense];
  const group = svgElement('g', { class: 'whorl', 'data-turn': turn });
  group.append(svgElement('path', { d: arc }), arrowhead([ex - tangent[0], ey - tangent[1]], [ex, ey], 10));
  group.append(svgElement('circle', { cx, cy, r: 3 }));
  return group;
}

function growthText() {
  if (growth.mode === 'flow') return 'Click along the way the hair grows; double-click to end the flow.';
  if (growth.mode === 'whorl') return `Click the ${$('whorl-turn').value} whorl's centre on the map.`;
  const count = (n, word) => `${n} ${word}${n === 1 ? '' : 's'}`;
  if (!growth.flows.length && !growth.whorls.length) return '';
  return `${count(growth.flows.length, 'flow')}, ${count(growth.whorls.length, 'whorl')}: the grafts placed grow along them`;
}

function drawGrowth() {
  $('growth-status').textContent = growthText();
  $('growth-status').dataset.flows = String(growth.flows.length);
  $('growth-status').dataset.whorls = String(growth.whorls.length);
  const svg = mapSvg();
  if (!svg) return;
  let group = svg.querySelector('g.growth-drawing');
  if (!group) {
    group = svgElement('g', { class: 'growth-drawing' });
    svg.append(group);
  }
  const flows = growth.flows.map((points) => flowElement(points, true));
  const whorls = growth.whorls.map(whorlElement);
  const { kind, index } = growth.error ?? {};
  ({ flow: flows, whorls })[kind]?.[index]?.classList.add('error');
  const drawing = growth.drawing ? [flowElement(growth.drawing, false)] : [];
  group.replaceChildren(...flows, ...drawing, ...whorls);
}

function setGrowthMode(mode) {
  growth.mode = mode;
  growth.drawing = mode === 'flow' ? [] : null;
  markDrawing();
  drawGrowth();
}

// A zone half drawn is given up: a click goes to one drawing at a time.
function startGrowth(mode) {
  if (zone.drawing) clearZone();
  cancelPlanZone();
  setGrowthMode(mode);
}

// Grafts placed with the old growth no longer show it: they go, as when the zone changes.
function growthChanged() {
  growth.error = null;
  if ($('sites-status').dataset.state !== 'none') clearSites();
  setGrowthMode(null);
}

function clickGrowth(event) {
  if (!growth.mode || event.detail > 1) return;
  const point = pictureAt(event);
  if (growth.mode === 'whorl') {
    growth.whorls.push({ point, turn: $('whorl-turn').value });
    growthChanged();
    return;
  }
  // A point on the last (the first click of the double click that ends) adds nothing.
  const last = growth.drawing.at(-1);
  if (!last || Math.hypot(point[0] - last[0], point[1] - last[1]) > 2) growth.drawing.push(point);
  drawGrowth();
}

function endFlow() {
  if (growth.mode !== 'flow' || growth.drawing.length < 2) return;
  growth.flows.push(growth.drawing);
  growthChanged();
}

function clearGrowth() {
  Object.assign(growth, { flows: [], whorls: [], error: null });
  if ($('sites-status').dataset.state !== 'none') clearSites();
  setGrowthMode(null);
}

// params.growth of the flows and whorls in the layout's coordinates; null without either.
function growthParams() {
  if (!growth.flows.length && !growth.whorls.length) return null;
  const flow = growth.flows.map((points, k) => {
    const layout = points.map(toLayout);
    return { name: `flow ${k + 1}`, x: layout.map((q) => q[0]), y: layout.map((q) => q[1]) };
  });
  const whorls = growth.whorls.map(({ point, turn }) => {
    const [x, y] = toLayout(point);
    return { x, y, turn };
  });
  const grows = { flow, whorls };
  // Blank: the service's default exit angle.
  if ($('exit-angle').value.trim()) grows.exit_angle_deg = Number($('exit-angle').value);
  return grows;
}

// -- a transplant plan: recipient and donor zones weighed by /v1/plan ------------------------

// The recipient and donor zones drawn (closed outlines in the picture's pixels, as the zone
// is), the one being drawn ({ kind, points }) or null, the zone the last refusal named
// ({ kind, index }) and the ticket of the planning that counts.
const transplant = { recipient: [], donor: [], drawing: null, error: null, ticket: 0 };
const planZoneName = (kind, index) => `${kind} ${index + 1}`;

// A zone of the plan: its outline in its kind's colour (service/capabilities/plan.py), with
// its points while drawn.
function planZoneElement(kind, points, closed, refused) {
  const group = svgElement('g', { class: `plan-zone ${kind}${closed ? '' : ' drawing'}${refused ? ' error' : ''}` });
  group.append(svgElement(closed ? 'polygon' : 'polyline', { points: pointsText(points) }));
  if (!closed) group.append(...points.map(([cx, cy]) => svgElement('circle', { cx, cy, r: 3 })));
  return group;
}

function planZonesText() {
  if (transplant.drawing) return `Click points on the map; double-click to close the ${transplant.drawing.kind} zone.`;
  const count = (n, word) => `${n} ${word} zone${n === 1 ? '' : 's'}`;
  if (!transplant.recipient.length && !transplant.donor.length) return '';
  return `${count(transplant.recipient.length, 'recipient')}, ${count(transplant.donor.length, 'donor')}`;
}

function drawPlanZones() {
  $('plan-zones').textContent = planZonesText();
  $('plan-zones').dataset.recipient = String(transplant.recipient.length);
  $('plan-zones').dataset.donor = String(transplant.donor.length);
  // A plan needs a recipient zone; without donor zones the balance is what is needed.
  $('plan').disabled = !map || !transplant.recipient.length;
  const svg = mapSvg();
  if (!svg) return;
  let group = svg.querySelector('g.plan-drawing');
  if (!group) {
    group = svgElement('g', { class: 'plan-drawing' });
    svg.append(group);
  }
  const { kind: refusedKind, index: refusedIndex } = transplant.error ?? {};
  const closed = ['recipient', 'donor'].flatMap((kind) =>
    transplant[kind].map((points, k) => planZoneElement(kind, points, true, kind === refusedKind && k === refusedIndex)),
  );
  const drawing = transplant.drawing ? [planZoneElement(transplant.drawing.kind, transplant.drawing.points, false, false)] : [];
  group.replaceChildren(...closed, ...drawing);
}

// The plan shown no longer fits once its zones change: it goes.
function clearPlanAnswer() {
  transplant.ticket += 1;
  $('plan-table').replaceChildren();
  $('plan-balance').replaceChildren();
  showStatus('plan-status', '', 'none');
}

function startPlanZone(kind) {
  if (zone.drawing) clearZone();
  setGrowthMode(null);
  Object.assign(transplant, { drawing: { kind, points: [] }, error: null });
  clearPlanAnswer();
  markDrawing();
  drawPlanZones();
}

// A plan's zone half drawn is given up when another drawing starts.
function cancelPlanZone() {
  if (!transplant.drawing) return;
  transplant.drawing = null;
  markDrawing();
  drawPlanZones();
}

function clickPlanZone(event) {
  if (!transplant.drawing || event.detail > 1) return;
  transplant.drawing.points.push(pictureAt(event));
  drawPlanZones();
}

function closePlanZone() {
  const drawn = transplant.drawing;
  if (!drawn || drawn.points.length < 3) return;
  transplant[drawn.kind].push(drawn.points);
  transplant.drawing = null;
  markDrawing();
  drawPlanZones();
}

function clearPlan() {
  Object.assign(transplant, { recipient: [], donor: [], drawing: null, error: null });
  clearPlanAnswer();
  markDrawing();
  drawPlanZones();
}

// A signed whole number, as the plan's caption gives the balance (+66, -14, 0).
const signed = (value) => Math.round(value).toLocaleString('en', { signDisplay: 'exceptZero' });

function showPlan(answer) {
  const whole = (n) => n.toLocaleString('en');
  const row = (kind, cells) => Object.assign(tableRow(cells, 'td'), { className: kind });
  const rows = [
    ...answer.recipient.map((z) => row('recipient', [z.name, z.area_cm2.toFixed(2), z.density_per_cm2.toFixed(1), whole(z.grafts_needed), '–'])),
    ...answer.donor.map((z) => row('donor', [z.name, z.area_cm2.toFixed(2), z.density_per_cm2.toFixed(1), '–', whole(z.grafts_available)])),
    row('total', ['total', '', '', whole(answer.grafts_needed), whole(answer.grafts_available)]),
  ];
  const names = ['zone', 'area (cm²)', 'grafts per cm²', 'grafts needed', 'grafts available'];
  $('plan-table').replaceChildren(tableRow(names, 'th'), ...rows);
  // Short (negative) is red; the numbers carry their sign.
  const part = (value, unit) =>
    Object.assign(document.createElement('span'), { textContent: `${signed(value)} ${unit}`, className: Math.round(value) < 0 ? 'short' : '' });
  const { balance, sessions } = answer;
  $('plan-balance').replaceChildren(
    'Balance: ',
    part(balance.grafts, 'grafts'),
    ', ',
    part(balance.hairs, 'hairs'),
    ` (available minus needed); ${whole(sessions)} session${sessions === 1 ? '' : 's'} of at most ${whole(answer.max_grafts_per_session)} grafts`,
  );
}

// The zones drawn, at the target density (recipient) and the density and hairs a graft
// measured (donor), to /v1/plan with the map's params and the units. A recipient zone
// takes the donor's hairs a graft (the service's pooled mean).
async function runPlan() {
  clearPlanAnswer();
  const ticket = transplant.ticket;
  const zones = (kind, numbers) => transplant[kind].map((points, k) => ({ name: planZoneName(kind, k), outer: layoutRing(points), ...numbers }));
  const p = {
    ...map.params,
    units: $('units').value,
    recipient: zones('recipient', { density_per_cm2: Number($('target-density').value) }),
    donor: zones('donor', { density_per_cm2: Number($('donor-density').value), hairs_per_graft: Number($('hairs-per-graft').value) }),
  };
  transplant.error = null;
  drawPlanZones();
  showStatus('plan-status', 'planning…', 'planning');
  try {
    const answer = await api.json('/v1/plan', { mesh: map.mesh }, p);
    if (ticket !== transplant.ticket) return; // the zones changed, or planned again, meanwhile
    showWarnings(answer);
    showPlan(answer);
    showStatus('plan-status', '', 'planned');
  } catch (error) {
    if (ticket !== transplant.ticket) return;
    showStatus('plan-status', error.message, 'error');
    // The zone the service refused (params.donor.0 overlaps ...): marked on the map.
    const named = /^params\.(recipient|donor)\.(\d+)/.exec(error.field ?? '');
    transplant.error = named ? { kind: named[1], index: Number(named[2]) } : null;
    drawPlanZones();
  }
}

// -- strands grown from the grafts by /v1/strands -------------------------------------------

// Points a strand (the service's default).
const HAIR_POINTS = 16;
let hair = null; // the strands in the 3D view
let hairTicket = 0;

function clearHair() {
  hairTicket += 1;
  if (hair) dispose(hair);
  hair = null;
  showStatus('hair-status', '', 'none');
  delete $('hair-status').dataset.count;
}

// The strands on the head: each one's segments (point j to j + 1), shaded from the root (dark)
// to the tip (hair brown) as the grafts' strokes are.
function showHair(answer) {
  const shade = (j, points) => STROKE_ROOT.clone().lerp(STROKE_TIP, j / (points - 1)).toArray();
  const ends = [];
  const colours = [];
  for (const strand of answer.points) {
    for (let j = 1; j < strand.length; j += 1) {
      ends.push(...strand[j - 1], ...strand[j]);
      colours.push(...shade(j - 1, strand.length), ...shade(j, strand.length));
    }
  }
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.Float32BufferAttribute(ends, 3));
  geometry.setAttribute('color', new THREE.Float32BufferAttribute(colours, 3));
  hair = new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ vertexColors: true }));
  hair.name = 'strands';
  scene.add(hair);
  const lengths = answer.length_mm.map(Math.round);
  const [shortest, longest] = [Math.min(...lengths), Math.max(...lengths)];
  const length = shortest === longest ? `${shortest}` : `${shortest}-${longest}`;
  showStatus('hair-status', `${answer.count.toLocaleString('en')} strands of ${length} mm`, 'grown');
  $('hair-status').dataset.count = String(answer.count);
}

// A strand from each graft shown: the params they were placed with (their growth, with the
// exit angle given) and the length given. Grafts placed without growth grow none: the
// service says so.
async function growHair() {
  clearHair();
  const ticket = hairTicket;
  const p = { ...placed, length_mm: Number($('hair-length').value), points: HAIR_POINTS, output: 'json' };
  showStatus('hair-status', 'growing…', 'growing');
  try {
    const answer = await api.json('/v1/strands', { mesh: map.mesh }, p);
    if (ticket !== hairTicket) return; // the grafts went, or grown again, meanwhile
    showWarnings(answer);
    showHair(answer);
  } catch (error) {
    if (ticket === hairTicket) showStatus('hair-status', error.message, 'error');
  }
}

// -- landmarks placed on the whole head -----------------------------------------------------

const LANDMARKS = ['nasion', 'inion', 'left_tragus', 'right_tragus', 'vertex'];
const REQUIRED = LANDMARKS.slice(0, 4);
const landmarks = { points: {}, head: null, markers: {}, picking: false, frame: null };
const raycaster = new THREE.Raycaster();

// The whole mesh, faint, for clicking the landmarks the region leaves out (the tragi, the
// nasion): /v1/flatten's GLB of every face, in the file's coordinates as the region's.
async function loadHead() {
  if (landmarks.head || !map) return;
  const p = { ...map.params, region: null, untangle: false, colour_by: 'flags' };
  const glb = await api.glb('/v1/flatten', { mesh: map.mesh }, p);
  const gltf = await new GLTFLoader().parseAsync(glb, '');
  gltf.scene.traverse((node) => {
    if (node.isMesh) node.material = new THREE.MeshLambertMaterial({ color: 0xb8c4cc, transparent: true, opacity: 0.55, side: THREE.DoubleSide });
  });
  landmarks.head = gltf.scene;
  landmarks.head.name = 'head';
  scene.add(landmarks.head);
}

async function startPicking() {
  $('pick').disabled = true;
  try {
    await loadHead();
    landmarks.picking = true;
    $('view').classList.add('picking');
    $('landmark-list').dataset.state = 'picking';
  } catch (error) {
    setStatus(error.message, true);
  } finally {
    $('pick').disabled = !map;
  }
}

function markLandmark(name, point) {
  if (landmarks.markers[name]) scene.remove(landmarks.markers[name]);
  const size = map ? map.size / 60 : 1;
  const marker = new THREE.Mesh(new THREE.SphereGeometry(size, 12, 8), new THREE.MeshBasicMaterial({ color: 0xd55e00 }));
  marker.position.set(...point);
  scene.add(marker);
  landmarks.markers[name] = marker;
}

function listLandmarks() {
  const placed = LANDMARKS.filter((name) => landmarks.points[name]);
  $('landmark-list').textContent = placed.map((n) => `${n}: ${landmarks.points[n].map((c) => c.toFixed(2)).join(', ')}`).join('\n');
  $('landmark-list').dataset.count = String(placed.length);
  $('landmark-list').dataset.points = JSON.stringify(landmarks.points);
  const ready = REQUIRED.every((name) => landmarks.points[name]);
  $('use-landmarks').disabled = !ready;
  if (!ready) $('use-landmarks').checked = false;
}

// A click on the 3D view while placing: the head's surface point under it, for the landmark
// selected; then the next one is selected.
function pickLandmark(event) {
  if (!landmarks.picking || !landmarks.head) return;
  const box = renderer.domElement.getBoundingClientRect();
  const pointer = new THREE.Vector2(((event.clientX - box.left) / box.width) * 2 - 1, -((event.clientY - box.top) / box.height) * 2 + 1);
  raycaster.setFromCamera(pointer, camera);
  const [hit] = raycaster.intersectObject(landmarks.head, true);
  if (!hit) return;
  const name = $('landmark').value;
  landmarks.points[name] = hit.point.toArray();
  markLandmark(name, landmarks.points[name]);
  listLandmarks();
  const next = LANDMARKS[(LANDMARKS.indexOf(name) + 1) % LANDMARKS.length];
  $('landmark').value = next;
}

function clearLandmarks() {
  Object.values(landmarks.markers).forEach((marker) => scene.remove(marker));
  Object.assign(landmarks, { points: {}, markers: {}, picking: false });
  $('view').classList.remove('picking');
  $('landmark').value = LANDMARKS[0];
  listLandmarks();
}

// The camera from a side of the head, by the frame of the map shown: local +Z is the front,
// -Y (away from the pole) the top, +X the right.
function viewFrom(side) {
  if (!map) return;
  const [x, y, z] = map.rotation.map((row) => new THREE.Vector3(...row));
  const direction = { front: z, back: z.clone().negate(), right: x, left: x.clone().negate(), top: y.clone().negate() }[side];
  camera.position.copy(controls.target).add(direction.multiplyScalar(map.size * 3));
  camera.up.copy(side === 'top' ? z : y.clone().negate());
  controls.update();
}

// For tests and integrations: where a world point shows in the page's pixels.
/** @type {any} */ (window).meshflatDemo = {
  project(point) {
    const box = renderer.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector3(...point).project(camera);
    return [box.left + ((ndc.x + 1) / 2) * box.width, box.top + ((1 - ndc.y) / 2) * box.height];
  },
  // The vertices of a line object of the 3D view by its name ('strands'), x y z after x y z.
  positions(name) {
    return Array.from(scene.getObjectByName(name)?.geometry.attributes.position.array ?? []);
  },
};

// -- the page -----------------------------------------------------------------------------

// The region's own fields: the cone's, or the colour threshold's.
$('region-kind').addEventListener('change', () => {
  const painted = $('region-kind').value === 'vertex_color';
  for (const label of document.querySelectorAll('label.cone-only')) /** @type {HTMLElement} */ (label).hidden = painted;
  for (const label of document.querySelectorAll('label.color-only')) /** @type {HTMLElement} */ (label).hidden = !painted;
});

function clearPresets() {
  // A file of one's own: the sample's region and frame do not fit it; the service chooses.
  $('apex').value = '';
  $('center').value = 'bbox_center';
  for (const id of ['pole', 'up', 'sigma', 'facing']) $(id).value = '';
  syncFrameFields();
}

// The isometric energy as the pictures' captions say it: the trusted faces' median and p95
// (a mean is dominated by a few stretched slivers) and how many faces are flagged.
function energy(trusted, v) {
  const stretched = v.stretched_faces ? `, ${v.stretched_faces} of them stretched` : '';
  if (!trusted) return 'isometric energy: no trusted face (every face is flagged)';
  const e = trusted.isometric;
  return `isometric energy p50 ${e.p50.toFixed(3)}, p95 ${e.p95.toFixed(3)} on the trusted faces (${trusted.flagged_faces} flagged${stretched})`;
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
    energy(extras.metrics.trusted, v),
    `flagged faces: back-facing ${v.backfacing_faces}, folded ${v.folded_faces}, seam ${v.seam_faces}, singular ${v.singular_point_faces}, stretched ${v.stretched_faces}`,
    ...untangled,
  ].join('\n');
}

// The picture's size: as wide as the map's place on the page, so that it is drawn at its own
// scale and its text (12 px and up) is not shrunk (the service's bounds: 480 to 4096 wide, at
// least 360 high).
function pictureSize() {
  const width = Math.min(4096, Math.max(480, Math.floor($('map').getBoundingClientRect().width)));
  return { image_width: width, image_height: Math.max(360, Math.round(width * 0.75)) };
}

// Where the front and the back of the head are on the map: with a front named (facing, or
// the landmarks'), the pictures put it at the top and theta grows downwards to the back
// (docs/math.md, section 18). Without one, no label: the roll follows the region.
function labelOrientation(facing) {
  if (!facing) return;
  const plot = mapSvg().querySelector('#plot rect');
  const [left, top, width, height] = ['x', 'y', 'width', 'height'].map((a) => Number(plot.getAttribute(a)));
  const group = svgElement('g', { class: 'orientation' });
  const label = (text, y, baseline) => {
    const element = svgElement('text', { x: left + width / 2, y, 'text-anchor': 'middle', 'dominant-baseline': baseline, class: text });
    element.textContent = text;
    return element;
  };
  group.append(label('front', top + 4, 'hanging'), label('back', top + height - 4, 'auto'));
  mapSvg().append(group);
}

// What is drawn on the map (the zone, flows and whorls, the plan's zones), in the layout's
// coordinates: the picture's pixels change with a new picture, the layout's points do not.
function drawingsInLayout() {
  const ring = (points) => points.map(toLayout);
  return {
    zone: ring(zone.points),
    flows: growth.flows.map(ring),
    whorls: growth.whorls.map((whorl) => ({ ...whorl, point: toLayout(whorl.point) })),
    recipient: transplant.recipient.map(ring),
    donor: transplant.donor.map(ring),
  };
}

// The drawings again on the new picture (the grafts from their answer's layout points).
function redraw(drawings) {
  const ring = (points) => points.map(toPicture);
  zone.points = ring(drawings.zone);
  growth.flows = drawings.flows.map(ring);
  growth.whorls = drawings.whorls.map((whorl) => ({ ...whorl, point: toPicture(whorl.point) }));
  transplant.recipient = drawings.recipient.map(ring);
  transplant.donor = drawings.donor.map(ring);
  if (zone.points.length) drawZone();
  drawGrowth();
  drawPlanZones();
  if (sitesShown) drawSitesOnMap(sitesShown);
}

// A drawing half done is given up: its clicks were on the picture that goes.
function stopDrawing() {
  if (zone.drawing) clearZone();
  if (growth.mode) setGrowthMode(null);
  cancelPlanZone();
}

// Whether two resolved maps differ: the centre, the rotation or sigma by more than the
// fields' six digits (a map sent back from the fields is the same map).
function mapMoved(before, after) {
  const numbers = (m) => [...m.center, ...m.rotation.flat(), m.sigma ?? 0];
  const [a, b] = [numbers(before), numbers(after)];
  return before.method !== after.method || a.some((value, i) => Math.abs(value - b[i]) > 1e-5 * Math.max(1, Math.abs(value)));
}

const shortNumber = (value) => String(Number(value.toPrecision(6)));
const vectorText = (values) => values.map(shortNumber).join(', ');

// The fields show what the answer used: the centre (fitted, or the box centre the name stood
// for), the pole (local +Y), the up (local +Z), sigma and where the face looks.
function showValuesUsed({ center, rotation, sigma, facing }) {
  $('center').value = vectorText(center);
  $('pole').value = vectorText(rotation[1]);
  $('up').value = vectorText(rotation[2]);
  $('sigma').value = sigma === null ? '' : shortNumber(sigma);
  if (facing) $('facing').value = vectorText(facing);
  syncFrameFields();
}

// The map picture and the 3D region for `p`: both from /v1/flatten (SVG at the map's size,
// GLB), shown, and `map` set. What is drawn on the map stays when `keep` (the same mesh,
// region and layout), carried to the new picture through the layout's coordinates.
async function showMap(mesh, p, keep) {
  const drawings = keep ? drawingsInLayout() : null;
  const [svgText, glb] = await Promise.all([
    api.svg('/v1/flatten', { mesh }, { ...p, ...pictureSize() }),
    api.glb('/v1/flatten', { mesh }, p),
  ]);
  const svg = new DOMParser().parseFromString(svgText, 'image/svg+xml').documentElement;
  svg.removeAttribute('width');
  svg.removeAttribute('height');
  $('map').replaceChildren(document.importNode(svg, true));
  const gltf = await new GLTFLoader().parseAsync(glb, '');
  const vertices = show(gltf);
  const extras = gltf.parser.json.asset.extras.meshflat;
  $('vertices').textContent = vertices.toLocaleString('en');
  $('summary').textContent = summary(extras);
  const { method, sigma, center, rotation, facing } = extras.params;
  const json = gltf.parser.json;
  const uv = json.accessors[json.meshes[0].primitives[0].attributes.TEXCOORD_0];
  const { frame: _frame, ...resolved } = p; // the landmarks resolve to this centre and rotation
  const size = new THREE.Box3().setFromObject(gltf.scene).getBoundingSphere(new THREE.Sphere()).radius;
  const before = map;
  map = { mesh, params: { ...resolved, method, sigma, center, rotation }, uv: { ...extras.uv, max: uv.max }, rotation, size };
  labelOrientation(facing);
  if (drawings) redraw(drawings);
  document.body.dataset.vertices = String(vertices);
  return { extras, vertices, moved: before !== null && mapMoved(before.params, map.params) };
}

// The map's tools, while there is a map to use them on.
function enableTools(enabled) {
  for (const id of ['draw', 'pick', 'place-sites', 'draw-flow', 'place-whorl', 'draw-recipient', 'draw-donor']) $(id).disabled = !enabled;
}

async function flatten(event) {
  event?.preventDefault();
  $('go').disabled = true;
  enableTools(false);
  if (landmarks.head) scene.remove(landmarks.head);
  landmarks.head = null;
  landmarks.picking = false;
  $('view').classList.remove('picking');
  stopDrawing();
  document.body.dataset.state = 'flattening';
  setStatus('flattening…');
  const started = performance.now();
  try {
    const mesh = await meshFile();
    const p = params();
    // The same mesh, region and layout: the zone, the grafts, the flows and whorls and the
    // plan's zones stay. Else they were drawn on a map that goes, and go with it.
    const keep = map !== null && map.mesh.source === mesh.source && map.params.layout === p.layout && JSON.stringify(map.params.region) === JSON.stringify(p.region);
    if (!keep) {
      clearGrowth();
      clearZone();
      map = null;
      clearPlan();
    }
    const { extras, moved } = await showMap(mesh, p, keep);
    showValuesUsed(extras.params);
    // Another map of the same region (another sigma, say): the numbers are made again on it.
    if (moved) refreshNumbers();
    enableTools(true);
    drawPlanZones();
    document.body.dataset.state = 'shown';
    setStatus(`done in ${Math.round(performance.now() - started)} ms`);
  } catch (error) {
    document.body.dataset.state = 'error';
    setStatus(error.message, true);
    enableTools(map !== null);
  } finally {
    $('go').disabled = false;
  }
}

// The zone's area, the grafts and the plan, asked again for the map shown; the strands go
// with the grafts they grew from.
function refreshNumbers() {
  const hadGrafts = sitesShown !== null; // measuring lets them go: they are placed again
  if (zone.closed) measure();
  if (hadGrafts) placeSites();
  if ($('plan-status').dataset.state !== 'none') runPlan();
}

// Another colouring: the same map again (its resolved centre, rotation and sigma: nothing is
// fitted again) with the new colours; what is drawn on it stays.
async function recolour() {
  if (!map) return;
  document.body.dataset.state = 'recolouring';
  setStatus('colouring…');
  try {
    await showMap(map.mesh, { ...map.params, colour_by: $('colour-by').value }, true);
    document.body.dataset.state = 'shown';
    setStatus('');
  } catch (error) {
    document.body.dataset.state = 'error';
    setStatus(error.message, true);
  }
}

// A file chosen: it is the source, and the sample selector says so.
function showUpload() {
  const upload = $('file').files[0];
  let option = $('sample').querySelector('option.upload');
  if (!upload) {
    option?.remove();
    return;
  }
  if (!option) {
    option = Object.assign(document.createElement('option'), { className: 'upload', value: '' });
    $('sample').prepend(option);
  }
  option.textContent = `uploaded: ${upload.name}`;
  $('sample').value = '';
}

// A sample chosen: the file chosen before is let go.
function chooseSample() {
  $('file').value = '';
  showUpload();
  applyPreset();
}

$('sample').addEventListener('change', chooseSample);
$('file').addEventListener('change', () => {
  clearPresets();
  showUpload();
});
$('apikey').addEventListener('change', loadSamples);
$('auto').addEventListener('change', syncFrameFields);
$('facing').addEventListener('input', syncFrameFields);
$('form').addEventListener('submit', flatten);
$('draw').addEventListener('click', startZone);
$('clear-zone').addEventListener('click', clearZone);
$('place-sites').addEventListener('click', placeSites);
$('pick').addEventListener('click', startPicking);
$('clear-landmarks').addEventListener('click', clearLandmarks);
$('view').addEventListener('click', pickLandmark);
document.querySelectorAll('button.view').forEach((button) => button.addEventListener('click', () => viewFrom(/** @type {HTMLElement} */ (button).dataset.view)));
$('units').addEventListener('change', () => zone.closed && measure());
// Another colouring: the map and the 3D view again, with it.
$('colour-by').addEventListener('change', recolour);
$('map').addEventListener('click', addPoint);
$('map').addEventListener('dblclick', closeZone);
$('draw-flow').addEventListener('click', () => startGrowth('flow'));
$('place-whorl').addEventListener('click', () => startGrowth('whorl'));
$('clear-growth').addEventListener('click', clearGrowth);
$('whorl-turn').addEventListener('change', drawGrowth);
$('map').addEventListener('click', clickGrowth);
$('map').addEventListener('dblclick', endFlow);
// Another exit angle: grafts placed with growth are placed again, with it.
$('exit-angle').addEventListener('change', () => strokes && placeSites());
$('grow-hair').addEventListener('click', growHair);
$('draw-recipient').addEventListener('click', () => startPlanZone('recipient'));
$('draw-donor').addEventListener('click', () => startPlanZone('donor'));
$('clear-plan').addEventListener('click', clearPlan);
$('map').addEventListener('click', clickPlanZone);
$('map').addEventListener('dblclick', closePlanZone);
$('plan').addEventListener('click', runPlan);
// Other units or numbers: a plan shown (or refused) is made again with them.
for (const id of ['units', 'target-density', 'donor-density', 'hairs-per-graft']) {
  $(id).addEventListener('change', () => $('plan-status').dataset.state !== 'none' && runPlan());
}
animate();
loadSamples().then(() => {
  document.body.dataset.state = 'ready';
});
