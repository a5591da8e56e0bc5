// Front end of `hgs view`: renders the model's Gaussians with @mkkellogg/gaussian-splats-3d (three.js, orbit
// controls), sends text queries to the server's JSON API, lists the matching objects, and shows the selected
// one highlighted (tinted), isolated or removed by reloading the splat scene from /api/model.ply with those
// options. A 2D panel shows the nearest training view with the mask overlay and a heatmap from the server.
import * as THREE from 'three';
import * as GS from '@mkkellogg/gaussian-splats-3d';
import './style.css';

const $ = (id) => document.getElementById(id);
const state = { scene: null, results: [], chosen: [], selected: null, show: 'all', text: '', view: 0, viewer: null,
  loading: null, rendered: '' };
window.hgsViewer = state;  // for tests and the console

async function api(path, opts) {
  const r = await fetch(path, opts);
  if (!r.ok) {
    let msg = `HTTP ${r.status}`;
    try { msg = (await r.json()).error || msg; } catch (e) { /* not JSON */ }
    throw new Error(msg);
  }
  return r.json();
}

function status(text, isError = false) {
  $('status').textContent = text;
  $('status').classList.toggle('error', isError);
}

// COLMAP world->camera (R row-major, t): camera x right, y down, z forward.
function camAxes(v) {
  const R = v.R;
  const row = (i) => new THREE.Vector3(R[3 * i], R[3 * i + 1], R[3 * i + 2]);
  return { right: row(0), down: row(1), forward: row(2), center: new THREE.Vector3(...v.center) };
}

function sceneUp(views) {
  const up = new THREE.Vector3();
  for (const v of views) up.sub(camAxes(v).down);
  return up.lengthSq() > 0 ? up.normalize() : new THREE.Vector3(0, 1, 0);
}

function viewPose(v) {
  const a = camAxes(v);
  const center = new THREE.Vector3(...state.scene.center);
  const d = Math.max(0.1, center.clone().sub(a.center).dot(a.forward));
  return { position: a.center, target: a.center.clone().add(a.forward.clone().multiplyScalar(d)) };
}

function modelUrl() {
  const k = state.selected;
  if (k == null || state.show === 'all') return '/api/model.ply';
  if (state.show === 'highlight') return `/api/model.ply?objects=${k}&tint=1`;
  return `/api/model.ply?objects=${k}&show=${state.show}`;
}

// (Re)creates the splat viewer on `url`, keeping the current camera pose.
async function loadSplats(url) {
  if (state.rendered === url) return;
  const seq = Symbol(url);
  state.loading = seq;
  document.body.dataset.state = 'loading';
  let pose = null;
  if (state.viewer) {
    pose = { position: state.viewer.camera.position.clone(), target: state.viewer.controls.target.clone() };
    const old = state.viewer;
    state.viewer = null;
    try {
      await old.dispose();
    } catch (e) {
      console.warn(`splat viewer dispose: ${e.message}`);
    }
    old.hgsRoot.remove();
  }
  if (!pose) pose = viewPose(state.scene.views[state.view]);
  const up = sceneUp(state.scene.views);
  const root = document.createElement('div');
  root.className = 'splats';
  $('stage').appendChild(root);
  const viewer = new GS.Viewer({
    rootElement: root,
    cameraUp: up.toArray(),
    initialCameraPosition: pose.position.toArray(),
    initialCameraLookAt: pose.target.toArray(),
    sharedMemoryForWorkers: false,
    gpuAcceleratedSort: false,
    sphericalHarmonicsDegree: 0,
    antialiased: true,
    logLevel: GS.LogLevel.None,
  });
  viewer.hgsRoot = root;
  state.viewer = viewer;
  await viewer.addSplatScene(url, { format: GS.SceneFormat.Ply, showLoadingUI: false, progressiveLoad: false,
    splatAlphaRemovalThreshold: 1 });
  viewer.start();
  if (state.loading !== seq) return;
  state.rendered = url;
  document.body.dataset.state = 'ready';
  document.body.dataset.show = state.show;
  document.body.dataset.selected = state.selected ?? '';
}

function jumpToView(i) {
  state.view = i;
  $('cameras').value = String(i);
  if (state.viewer) {
    const p = viewPose(state.scene.views[i]);
    state.viewer.camera.position.copy(p.position);
    state.viewer.controls.target.copy(p.target);
    state.viewer.controls.update();
  }
  updatePanel(i);
}

function nearestView() {
  const views = state.scene.views;
  const train = views.filter((v) => !v.test);
  const pool = train.length ? train : views;
  if (!state.viewer) return state.view;
  const p = state.viewer.camera.position;
  let best = pool[0];
  for (const v of pool) if (p.distanceToSquared(camAxes(v).center) < p.distanceToSquared(camAxes(best).center)) best = v;
  return best.index;
}

function updatePanel(i = nearestView()) {
  state.view = i;
  const v = state.scene.views[i];
  $('panel-view').textContent = v.name;
  const ids = state.selected != null ? [state.selected] : state.chosen;
  if (!ids.length) {
    $('img-overlay').src = `/api/views/${i}/image.png`;
    $('img-heatmap').removeAttribute('src');
    return;
  }
  $('img-overlay').src = `/api/views/${i}/overlay.png?objects=${ids.join(',')}`;
  const mode = $('heat-mode').value;
  $('img-heatmap').src = mode === 'pixel' && state.text
    ? `/api/views/${i}/heatmap.png?mode=pixel&text=${encodeURIComponent(state.text)}`
    : `/api/views/${i}/heatmap.png?objects=${ids.join(',')}`;
}

function renderResults() {
  const ol = $('results');
  ol.replaceChildren();
  for (const r of state.results) {
    const li = document.createElement('li');
    li.dataset.id = r.id;
    li.classList.toggle('chosen', state.chosen.includes(r.id));
    li.classList.toggle('selected', r.id === state.selected);
    li.innerHTML = '<span class="name"></span> <span class="score"></span>';
    li.querySelector('.name').textContent = `${r.name} (#${r.id})`;
    li.querySelector('.score').textContent = r.relevancy.toFixed(3);
    li.addEventListener('click', () => select(r.id));
    ol.appendChild(li);
  }
}

async function select(id, show = 'highlight') {
  state.selected = id;
  state.show = id == null ? 'all' : show;
  renderResults();
  const has = id != null;
  for (const b of ['btn-highlight', 'btn-isolate', 'btn-remove']) $(b).disabled = !has;
  for (const [a, href] of [['dl-object', `/api/export.ply?objects=${id}`], ['dl-without', `/api/export.ply?objects=${id}&remove=1`]]) {
    $(a).classList.toggle('disabled', !has);
    if (has) $(a).href = href; else $(a).removeAttribute('href');
  }
  updatePanel(state.view);
  try {
    await loadSplats(modelUrl());
  } catch (e) {
    status(`render: ${e.message}`, true);
  }
}

async function runQuery(text) {
  status(`searching "${text}"…`);
  try {
    const a = await api('/api/query', { method: 'POST', headers: { 'Content-Type': 'application/json' },
      body: JSON.stringify({ text }) });
    state.text = text;
    state.results = a.results;
    state.chosen = a.chosen.map((c) => c.id);
    const best = a.chosen[0];
    status(`"${text}" → ${best.name} (${(a.seconds * 1000).toFixed(1)} ms)`);
    await select(best.id, 'highlight');
  } catch (e) {
    status(e.message, true);
  }
}

async function main() {
  try {
    state.scene = await api('/api/scene');
  } catch (e) {
    status(`cannot load the scene: ${e.message}`, true);
    document.body.dataset.state = 'error';
    return;
  }
  const s = state.scene;
  $('scene-name').textContent = `${s.scene} · ${s.gaussians} Gaussians · ${s.objects.length} objects`;
  for (const p of s.phrases) {
    const o = document.createElement('option');
    o.value = p;
    $('phrases').appendChild(o);
  }
  for (const v of s.views) {
    const o = document.createElement('option');
    o.value = String(v.index);
    o.textContent = `${v.name}${v.test ? ' (test)' : ''}`;
    $('cameras').appendChild(o);
  }
  state.results = s.objects.map((o) => ({ id: o.id, name: o.name, relevancy: 0 }));
  renderResults();
  $('query-form').addEventListener('submit', (e) => {
    e.preventDefault();
    const t = $('query').value.trim();
    if (t) runQuery(t);
  });
  for (const b of ['btn-highlight', 'btn-isolate', 'btn-remove'])
    $(b).addEventListener('click', () => select(state.selected, $(b).dataset.show));
  $('btn-all').addEventListener('click', () => { state.show = 'all'; loadSplats(modelUrl()); });
  $('cameras').addEventListener('change', () => jumpToView(Number($('cameras').value)));
  $('btn-nearest').addEventListener('click', () => updatePanel());
  $('heat-mode').addEventListener('change', () => updatePanel(state.view));
  const first = s.views.findIndex((v) => !v.test);
  state.view = first >= 0 ? first : 0;
  $('cameras').value = String(state.view);
  updatePanel(state.view);
  try {
    await loadSplats(modelUrl());
    status('ready: type a query');
  } catch (e) {
    status(`render: ${e.message}`, true);
    document.body.dataset.state = 'error';
  }
}

main();
