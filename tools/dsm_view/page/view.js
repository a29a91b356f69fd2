// dsm-view's page: pictures of a deep shadow map fetched tile by tile from
// the server (/api/picture), pan and zoom, a pixel's visibility function
// (/api/pixel), tile statistics (/api/tile), two maps side by side or their
// difference. Plain JavaScript, no framework. window.dsmView exposes the
// state for the browser tests (tests/tools/dsm_view_browser_test.py).
'use strict';

const TILE = 256;            // level pixels per side of a fetched picture
const MAX_FETCHES = 4;       // requests in flight at once
const PIN_COLOURS = ['#ffd54f', '#4fc3f7', '#ef5350', '#81c784', '#ba68c8', '#ff8a65', '#e0e0e0'];

const $ = (id) => document.getElementById(id);

const state = {
  maps: [],           // from /api/maps
  ramp: [],           // 256 RGB triples in [0, 1]
  compare: 'a',       // a | b | side | diff
  kind: 'opacity',
  channel: 'colour',
  level: 'auto',
  sliceZ: 0,
  radius: 1,
  zoom: 1,            // screen pixels per level-0 pixel
  centre: [0, 0],     // level-0 pixel coordinates at the panels' centre
  cursor: null,       // level-0 position under the mouse, shown in every panel
  pixels: [],         // plotted functions: {map, level, x, y, data, pinned, colour}
  scaleMax: 0,        // heat map and difference scale
  firstPictureMs: null,
};

const tiles = new Map();   // key -> {values, channels, w, h, canvas, colouring}
const lastLoaded = new Map();  // source|level|tx|ty -> the tile drawn while a refined one loads
const queue = [];          // keys waiting to be fetched
let inFlight = 0;
let pending = 0;           // fetches queued or in flight

// ---------------------------------------------------------------------------
// Maps, levels and what each panel shows

function info(m) { return state.maps[m].info; }

/// A map's file name without its directories, for titles.
function mapName(m) { return state.maps[m].name.split('/').pop(); }

/// The maps shown by panel p: [map] or [map, minus] for a difference.
function panelSource(p) {
  switch (state.compare) {
    case 'b': return p === 0 ? [1] : null;
    case 'side': return [p];
    case 'diff': return p === 0 ? [0, 1] : null;
    default: return p === 0 ? [0] : null;
  }
}

function panelCount() { return state.compare === 'side' ? 2 : 1; }

/// The level shown: chosen, or the finest whose pixels are at least a screen
/// pixel (so a huge map opens with a small level, and refines when zoomed).
function shownLevel(m) {
  const levels = info(m).levels;
  if (state.level !== 'auto') return Math.min(Number(state.level), levels.length - 1);
  let best = 0;
  for (let l = 0; l < levels.length; ++l)
    if (info(m).width / levels[l].width <= Math.max(1, 1 / state.zoom) + 1e-9) best = l;
  return best;
}

function levelScale(m, level) { return info(m).width / info(m).levels[level].width; }

function pictureKind() { return state.kind === 'tiles' ? 'opacity' : state.kind; }

function isCount() { return state.kind === 'vertices' || state.kind === 'layers'; }

function tileKey(source, level, tx, ty) {
  const kind = pictureKind();
  let key = `${source.join('-')}|${kind}|${level}|${tx}|${ty}`;
  if (kind === 'slice' || kind === 'soft') key += `|${state.sliceZ}`;
  if (kind === 'soft') key += `|${state.radius}|${state.softSamples || 16}`;
  return key;
}

function tileUrl(source, level, tx, ty) {
  const L = info(source[0]).levels[level];
  const x = tx * TILE, y = ty * TILE;
  const params = new URLSearchParams({
    map: source[0], level, kind: pictureKind(), x, y,
    w: Math.min(TILE, L.width - x), h: Math.min(TILE, L.height - y),
  });
  if (source.length > 1) params.set('minus', source[1]);
  if (pictureKind() === 'slice' || pictureKind() === 'soft') params.set('z', state.sliceZ);
  if (pictureKind() === 'soft') {
    params.set('radius', state.radius);
    params.set('samples', state.softSamples || 16);
  }
  return '/api/picture?' + params;
}

// ---------------------------------------------------------------------------
// Fetching tiles

function request(source, level, tx, ty) {
  const key = tileKey(source, level, tx, ty);
  if (tiles.has(key)) return tiles.get(key);
  const tile = { loading: true, source, level, tx, ty, key };
  tiles.set(key, tile);
  queue.push(key);
  ++pending;
  pump();
  return tile;
}

function pump() {
  while (inFlight < MAX_FETCHES && queue.length) {
    const key = queue.shift();
    const tile = tiles.get(key);
    if (!tile) { --pending; continue; }
    ++inFlight;
    fetch(tileUrl(tile.source, tile.level, tile.tx, tile.ty))
      .then(async (response) => {
        if (!response.ok) throw new Error((await response.json()).error || response.statusText);
        tile.channels = Number(response.headers.get('X-Channels'));
        tile.values = new Float32Array(await response.arrayBuffer());
        const L = info(tile.source[0]).levels[tile.level];
        tile.w = Math.min(TILE, L.width - tile.tx * TILE);
        tile.h = Math.min(TILE, L.height - tile.ty * TILE);
        tile.loading = false;
        if (tiles.get(tile.key) === tile)
          lastLoaded.set(`${tile.source.join('-')}|${tile.level}|${tile.tx}|${tile.ty}`, tile);
        growScale(tile);
      })
      .catch((error) => { tile.error = String(error.message || error); tile.loading = false; showError(tile.error); })
      .finally(() => {
        --inFlight;
        --pending;
        pump();
        draw();
      });
  }
}

/// Heat maps and differences are scaled to the largest value seen so far.
function growScale(tile) {
  if (!isCount() && state.compare !== 'diff') return;
  if (tile.level !== shownLevel(tile.source[0])) return;  // a preview's counts are of coarser pixels
  let most = state.scaleMax;
  for (const v of tile.values) most = Math.max(most, Math.abs(v));
  if (most > state.scaleMax) {
    state.scaleMax = most;
    drawScale();
  }
}

function showError(message) { $('readout').textContent = 'error: ' + message; }

// ---------------------------------------------------------------------------
// Colours

function colouringKey() { return `${state.kind}|${state.channel}|${state.compare}|${state.scaleMax}`; }

function byte(v) { return Math.round(255 * Math.min(1, Math.max(0, v))); }

/// RGBA of one pixel's values: grey levels round(255 v) (as dsm-info's 8-bit
/// pictures), the ramp for counts, red/blue for positive/negative differences.
function colourOf(values, i, channels, out, o) {
  const channel = state.channel === 'colour' ? -1 : Math.min(Number(state.channel), channels - 1);
  if (state.compare === 'diff') {
    const d = channel < 0 ? (channels === 3 ? (values[i] + values[i + 1] + values[i + 2]) / 3 : values[i])
                          : values[i + channel];
    const t = state.scaleMax > 0 ? d / state.scaleMax : 0;
    out[o] = byte(t); out[o + 1] = 0; out[o + 2] = byte(-t); out[o + 3] = 255;
  } else if (isCount()) {
    const t = state.scaleMax > 0 ? values[i] / state.scaleMax : 0;
    const c = state.ramp[Math.round(255 * Math.min(1, Math.max(0, t)))] || [0, 0, 0];
    out[o] = byte(c[0]); out[o + 1] = byte(c[1]); out[o + 2] = byte(c[2]); out[o + 3] = 255;
  } else if (channel < 0 && channels === 3) {
    out[o] = byte(values[i]); out[o + 1] = byte(values[i + 1]); out[o + 2] = byte(values[i + 2]); out[o + 3] = 255;
  } else {
    const g = byte(values[i + Math.max(0, channel)]);
    out[o] = g; out[o + 1] = g; out[o + 2] = g; out[o + 3] = 255;
  }
}

function tileCanvas(tile) {
  const key = colouringKey();
  if (tile.canvas && tile.colouring === key) return tile.canvas;
  if (!tile.canvas) {
    tile.canvas = document.createElement('canvas');
    tile.canvas.width = tile.w;
    tile.canvas.height = tile.h;
  }
  const context = tile.canvas.getContext('2d');
  const image = context.createImageData(tile.w, tile.h);
  for (let p = 0; p < tile.w * tile.h; ++p) colourOf(tile.values, p * tile.channels, tile.channels, image.data, p * 4);
  context.putImageData(image, 0, 0);
  tile.colouring = key;
  return tile.canvas;
}

function drawScale() {
  const bar = $('scale-bar');
  const context = bar.getContext('2d');
  const labels = $('scale-labels');
  if (!isCount() && state.compare !== 'diff') {
    const gradient = context.createLinearGradient(0, 0, 256, 0);
    gradient.addColorStop(0, '#000');
    gradient.addColorStop(1, '#fff');
    context.fillStyle = gradient;
    context.fillRect(0, 0, 256, 12);
    labels.innerHTML = `<span>0</span><span>${state.kind === 'opacity' ? 'opacity' : 'visibility'}</span><span>1</span>`;
    return;
  }
  const image = context.createImageData(256, 12);
  const probe = new Float32Array(1);
  for (let x = 0; x < 256; ++x) {
    probe[0] = state.compare === 'diff' ? (x / 255 * 2 - 1) * state.scaleMax : x / 255 * state.scaleMax;
    const saved = state.channel;
    state.channel = '0';
    const rgba = [0, 0, 0, 0];
    colourOf(probe, 0, 1, rgba, 0);
    state.channel = saved;
    for (let y = 0; y < 12; ++y) image.data.set(rgba, (y * 256 + x) * 4);
  }
  context.putImageData(image, 0, 0);
  const most = Number(state.scaleMax.toPrecision(4));
  const what = state.compare === 'diff' ? 'A − B' : state.kind === 'layers' ? 'layers' : 'vertices';
  labels.innerHTML = state.compare === 'diff' ? `<span>−${most}</span><span>${what}</span><span>+${most}</span>`
                                              : `<span>0</span><span>${what}</span><span>${most}</span>`;
}

// ---------------------------------------------------------------------------
// Drawing the panels

function panels() { return [0, 1].map((p) => $('panel-' + p)); }

/// Screen position in panel canvas of a level-0 position, and back.
function toScreen(canvas, point) {
  return [(point[0] - state.centre[0]) * state.zoom + canvas.width / 2,
          (point[1] - state.centre[1]) * state.zoom + canvas.height / 2];
}
function toMap(canvas, sx, sy) {
  return [(sx - canvas.width / 2) / state.zoom + state.centre[0], (sy - canvas.height / 2) / state.zoom + state.centre[1]];
}

let drawScheduled = false;
function draw() {
  if (drawScheduled) return;
  drawScheduled = true;
  requestAnimationFrame(() => { drawScheduled = false; drawNow(); });
}

/// Shows the panels the comparison needs (before anything measures them).
function layoutPanels() {
  panels().forEach((panel, p) => { panel.hidden = !panelSource(p); });
}

function drawNow() {
  layoutPanels();
  panels().forEach((panel, p) => {
    const source = panelSource(p);
    if (!source) return;
    const canvas = panel.querySelector('canvas');
    if (canvas.width !== panel.clientWidth || canvas.height !== panel.clientHeight) {
      canvas.width = panel.clientWidth;
      canvas.height = panel.clientHeight;
    }
    const context = canvas.getContext('2d');
    context.imageSmoothingEnabled = false;
    context.fillStyle = '#000';
    context.fillRect(0, 0, canvas.width, canvas.height);
    const m = source[0];
    const level = shownLevel(m);
    if (p === 0) state.shownLevel = level;
    const scale = levelScale(m, level);
    const L = info(m).levels[level];
    // Until the level's tiles are all here, a level 8 times coarser (a few
    // small requests, sent first) fills the panel.
    const preview = Math.min(info(m).levels.length - 1, level + 3);
    const loaded = (l) => visibleTiles(canvas, m, l).every(([tx, ty]) => {
      const tile = tiles.get(tileKey(source, l, tx, ty));
      return tile && tile.values;
    });
    if (preview !== level && !loaded(level)) {
      drawLevel(canvas, context, source, preview);
      if (loaded(preview) && state.previewMs === undefined && p === 0) state.previewMs = performance.now();
    }
    const complete = drawLevel(canvas, context, source, level);
    if (state.kind === 'tiles') drawTileGrid(canvas, context, m, level, scale);
    drawMarks(canvas, context, m);
    panel.querySelector('.title').textContent =
      `${source.length > 1 ? `${mapName(0)} − ${mapName(1)}` : mapName(m)} · level ${level} (${L.width} × ${L.height})`;
    if (complete && state.firstPictureMs === null && p === 0) {
      state.firstPictureMs = performance.now();
      document.body.dataset.firstPicture = 'drawn';
    }
  });
}

/// The [tx, ty] of a level's pictures that the panel's canvas shows.
function visibleTiles(canvas, m, level) {
  const scale = levelScale(m, level);
  const L = info(m).levels[level];
  const [x0, y0] = toMap(canvas, 0, 0), [x1, y1] = toMap(canvas, canvas.width, canvas.height);
  const span = TILE * scale;
  const list = [];
  for (let ty = Math.max(0, Math.floor(y0 / span)); ty <= Math.min(Math.ceil(L.height / TILE) - 1, Math.floor(y1 / span)); ++ty)
    for (let tx = Math.max(0, Math.floor(x0 / span)); tx <= Math.min(Math.ceil(L.width / TILE) - 1, Math.floor(x1 / span)); ++tx)
      list.push([tx, ty]);
  return list;
}

/// Draws (and asks for) a level's pictures in view; true when all are here.
function drawLevel(canvas, context, source, level) {
  const scale = levelScale(source[0], level);
  const span = TILE * scale;
  let complete = true;
  for (const [tx, ty] of visibleTiles(canvas, source[0], level)) {
    let tile = request(source, level, tx, ty);
    if (tile.loading || tile.error) {
      complete = false;
      tile = lastLoaded.get(`${source.join('-')}|${level}|${tx}|${ty}`);
      if (!tile) continue;
    }
    const [sx, sy] = toScreen(canvas, [tx * span, ty * span]);
    context.drawImage(tileCanvas(tile), sx, sy, tile.w * scale * state.zoom, tile.h * scale * state.zoom);
  }
  return complete;
}

function drawTileGrid(canvas, context, m, level, scale) {
  const span = info(m).tile_size * scale;
  const L = info(m).levels[level];
  if (span * state.zoom < 4) return;  // too dense to see
  context.strokeStyle = 'rgba(0, 200, 255, 0.7)';
  context.lineWidth = 1;
  context.beginPath();
  const [ox, oy] = toScreen(canvas, [0, 0]);
  const [ex, ey] = toScreen(canvas, [L.width * scale, L.height * scale]);
  for (let t = 0; t <= L.tiles_x; ++t) {
    const x = Math.round(toScreen(canvas, [Math.min(t * span, L.width * scale), 0])[0]) + 0.5;
    context.moveTo(x, Math.max(0, oy)); context.lineTo(x, Math.min(canvas.height, ey));
  }
  for (let t = 0; t <= L.tiles_y; ++t) {
    const y = Math.round(toScreen(canvas, [0, Math.min(t * span, L.height * scale)])[1]) + 0.5;
    context.moveTo(Math.max(0, ox), y); context.lineTo(Math.min(canvas.width, ex), y);
  }
  context.stroke();
}

/// The linked cursor and the plotted pixels, in every panel.
function drawMarks(canvas, context, m) {
  for (const px of state.pixels) {
    const scale = levelScale(px.map, px.level);
    const [sx, sy] = toScreen(canvas, [px.x * scale, px.y * scale]);
    context.strokeStyle = px.colour;
    context.lineWidth = 2;
    context.strokeRect(sx - 2, sy - 2, scale * state.zoom + 4, scale * state.zoom + 4);
  }
  if (state.cursor) {
    const [sx, sy] = toScreen(canvas, state.cursor);
    context.strokeStyle = 'rgba(255, 255, 255, 0.8)';
    context.lineWidth = 1;
    context.beginPath();
    context.moveTo(sx - 10, sy); context.lineTo(sx + 10, sy);
    context.moveTo(sx, sy - 10); context.lineTo(sx, sy + 10);
    context.stroke();
  }
}

/// The values under a level-0 position in panel p, from the fetched tiles.
function valuesAt(p, point) {
  const source = panelSource(p);
  const level = shownLevel(source[0]);
  const scale = levelScale(source[0], level);
  const x = Math.floor(point[0] / scale), y = Math.floor(point[1] / scale);
  const L = info(source[0]).levels[level];
  if (x < 0 || y < 0 || x >= L.width || y >= L.height) return null;
  const tile = tiles.get(tileKey(source, level, Math.floor(x / TILE), Math.floor(y / TILE)));
  if (!tile || !tile.values) return { level, x, y, values: null };
  const i = ((y % TILE) * tile.w + (x % TILE)) * tile.channels;
  return { level, x, y, values: Array.from(tile.values.subarray(i, i + tile.channels)) };
}

// ---------------------------------------------------------------------------
// Mouse: pan, zoom, hover, click

function fit() {
  layoutPanels();
  const panel = $('panel-0');
  const w = info(0).width, h = info(0).height;
  state.zoom = Math.min(panel.clientWidth / w, panel.clientHeight / h) * 0.98;
  state.centre = [w / 2, h / 2];
  draw();
}

/// Sets zoom and the level-0 position at the top-left corner of the panels.
function setView(zoom, left, top) {
  layoutPanels();
  const panel = $('panel-0');
  state.zoom = zoom;
  state.centre = [left + panel.clientWidth / 2 / zoom, top + panel.clientHeight / 2 / zoom];
  draw();
}

function installMouse(p) {
  const canvas = $('panel-' + p).querySelector('canvas');
  let drag = null;
  canvas.addEventListener('mousedown', (e) => { drag = { x: e.offsetX, y: e.offsetY, moved: false }; });
  window.addEventListener('mouseup', () => { setTimeout(() => { drag = null; }, 0); });
  canvas.addEventListener('mousemove', (e) => {
    if (drag && e.buttons) {
      const dx = e.offsetX - drag.x, dy = e.offsetY - drag.y;
      if (Math.abs(dx) + Math.abs(dy) > 2) drag.moved = true;
      if (drag.moved) {
        state.centre[0] -= dx / state.zoom;
        state.centre[1] -= dy / state.zoom;
        drag.x = e.offsetX; drag.y = e.offsetY;
      }
    }
    state.cursor = toMap(canvas, e.offsetX, e.offsetY);
    hover(p);
    draw();
  });
  canvas.addEventListener('mouseleave', () => { state.cursor = null; draw(); });
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    const before = toMap(canvas, e.offsetX, e.offsetY);
    state.zoom *= Math.pow(1.0015, -e.deltaY);
    const after = toMap(canvas, e.offsetX, e.offsetY);
    state.centre[0] += before[0] - after[0];
    state.centre[1] += before[1] - after[1];
    draw();
  }, { passive: false });
  canvas.addEventListener('click', (e) => {
    if (drag && drag.moved) return;
    const point = toMap(canvas, e.offsetX, e.offsetY);
    const source = panelSource(p);
    const level = shownLevel(source[0]);
    const scale = levelScale(source[0], level);
    selectPixel(Math.floor(point[0] / scale), Math.floor(point[1] / scale), level, e.shiftKey);
  });
}

function hover(p) {
  const lines = [];
  for (let q = 0; q < panelCount(); ++q) {
    const at = valuesAt(q, state.cursor);
    if (!at) continue;
    const source = panelSource(q);
    const name = source.length > 1 ? 'A − B' : mapName(source[0]);
    const values = at.values ? at.values.map((v) => Number(v.toPrecision(6))).join(', ') : '…';
    lines.push(`${name}  level ${at.level}  pixel ${at.x},${at.y}  ${pictureKind()} ${values}`);
  }
  $('readout').textContent = lines.join('\n') || ' ';
  if (state.kind === 'tiles') showTileStats(p);
}

const tileStats = new Map();
function showTileStats(p) {
  const m = panelSource(p)[0];
  const level = shownLevel(m);
  const scale = levelScale(m, level);
  const size = info(m).tile_size;
  const tx = Math.floor(state.cursor[0] / scale / size), ty = Math.floor(state.cursor[1] / scale / size);
  const L = info(m).levels[level];
  if (tx < 0 || ty < 0 || tx >= L.tiles_x || ty >= L.tiles_y) return;
  const key = `${m}|${level}|${tx}|${ty}`;
  const show = (t) => {
    $('tile-stats').textContent =
      `tile ${t.tx},${t.ty} of level ${t.level}: pixels ${t.x}-${t.x + t.width - 1} × ${t.y}-${t.y + t.height - 1}\n` +
      `  ${t.vertices} vertices, ${t.non_empty_pixels} non-empty pixels, ${t.stored_bytes} bytes stored ` +
      `(${t.raw_bytes} raw)\n  z ${t.stored_bytes ? t.min_z + ' to ' + t.max_z : '-'}`;
  };
  if (tileStats.has(key)) { if (tileStats.get(key)) show(tileStats.get(key)); return; }
  tileStats.set(key, null);
  fetch(`/api/tile?map=${m}&level=${level}&tx=${tx}&ty=${ty}`).then((r) => r.json()).then((t) => {
    tileStats.set(key, t);
    show(t);
  });
}

// ---------------------------------------------------------------------------
// A pixel's function

/// Plots pixel (x, y) of `level` of the shown map(s). Shift keeps the pixels
/// plotted so far (pinned); a plain click replaces the unpinned ones.
async function selectPixel(x, y, level, pin) {
  if (!pin) state.pixels = state.pixels.filter((px) => px.pinned);
  const shown = state.compare === 'b' ? [1] : state.compare === 'a' ? [0] : state.maps.map((_, i) => i);
  for (const m of shown) {
    const L = info(m).levels[Math.min(level, info(m).levels.length - 1)];
    if (x < 0 || y < 0 || x >= L.width || y >= L.height) continue;
    const response = await fetch(`/api/pixel?map=${m}&level=${level}&x=${x}&y=${y}`);
    const data = await response.json();
    if (!response.ok) { showError(data.error); continue; }
    state.pixels.push({ map: m, level, x, y, data, pinned: pin, colour: PIN_COLOURS[state.pixels.length % PIN_COLOURS.length] });
  }
  showPins();
  plot();
  vertexTable();
  draw();
}

function showPins() {
  const pins = $('pins');
  pins.innerHTML = '';
  state.pixels.forEach((px, i) => {
    const chip = document.createElement('span');
    chip.style.background = px.colour;
    chip.textContent = `${state.maps.length > 1 ? 'AB'[px.map] + ' ' : ''}${px.x},${px.y} L${px.level}${px.pinned ? ' ✕' : ''}`;
    chip.title = 'click to remove';
    chip.onclick = () => { state.pixels.splice(i, 1); showPins(); plot(); vertexTable(); draw(); };
    pins.appendChild(chip);
  });
}

/// The polyline of one layer: V = 1 before its first vertex, linear between
/// vertices (equal z is a vertical step), the last value after the last.
function layerPoints(data, layer, channel, zLeft, zRight) {
  const vs = data.vertices.filter((v) => v.layer === layer);
  if (!vs.length) return [];
  const points = [[zLeft, 1], [vs[0].z, 1]];
  for (const v of vs) points.push([v.z, v.value[channel]]);
  points.push([zRight, vs[vs.length - 1].value[channel]]);
  return points;
}

/// Light-centre V(z) (layer 0) of a plotted function, for the hover readout.
function evaluate(data, z, channel) {
  const vs = data.vertices.filter((v) => v.layer === 0);
  if (!vs.length || z < vs[0].z) return 1;
  for (let i = 1; i < vs.length; ++i)
    if (z < vs[i].z) {
      const a = vs[i - 1], b = vs[i];
      return a.value[channel] + (b.value[channel] - a.value[channel]) * (z - a.z) / (b.z - a.z);
    }
  return vs[vs.length - 1].value[channel];
}

const plotFrame = { left: 46, right: 10, top: 10, bottom: 28 };
let plotRange = [0, 1];

function plot() {
  const canvas = $('plot');
  const context = canvas.getContext('2d');
  context.clearRect(0, 0, canvas.width, canvas.height);
  const f = plotFrame;
  const w = canvas.width - f.left - f.right, h = canvas.height - f.top - f.bottom;
  let zMin = Infinity, zMax = -Infinity;
  for (const px of state.pixels) for (const v of px.data.vertices) { zMin = Math.min(zMin, v.z); zMax = Math.max(zMax, v.z); }
  if (!isFinite(zMin)) { zMin = 0; zMax = 1; }
  const margin = Math.max((zMax - zMin) * 0.08, 1e-3 * Math.max(1, Math.abs(zMax)));
  plotRange = [zMin - margin, zMax + margin];
  const X = (z) => f.left + (z - plotRange[0]) / (plotRange[1] - plotRange[0]) * w;
  const Y = (v) => f.top + (1 - v) * h;
  // Axes and labels.
  context.strokeStyle = '#666';
  context.fillStyle = '#aaa';
  context.font = '11px sans-serif';
  context.strokeRect(f.left, f.top, w, h);
  for (const v of [0, 0.25, 0.5, 0.75, 1]) { context.fillText(v.toFixed(2), 8, Y(v) + 4); }
  for (let k = 0; k <= 4; ++k) {
    const z = plotRange[0] + (plotRange[1] - plotRange[0]) * k / 4;
    context.fillText(Number(z.toPrecision(4)).toString(), X(z) - 14, canvas.height - 14);
  }
  context.fillText('light-space depth z', f.left + w / 2 - 40, canvas.height - 2);
  const plotted = [];
  for (const px of state.pixels) {
    const data = px.data;
    const channels = data.channels === 3 && state.channel === 'colour' ? [0, 1, 2]
                   : [data.channels === 3 && state.channel !== 'colour' ? Number(state.channel) : 0];
    const channelColours = ['#ff6b6b', '#69db7c', '#74c0fc'];
    const dashed = px.map === 1 && state.maps.length > 1;
    for (let layer = 0; layer < data.layers; ++layer)
      for (const c of channels) {
        const colour = channels.length > 1 ? channelColours[c] : px.colour;
        const points = layerPoints(data, layer, c, plotRange[0], plotRange[1]);
        if (!points.length) continue;
        // The level's error band around the function.
        context.fillStyle = colour + '30';
        context.beginPath();
        points.forEach(([z, v], i) => (i ? context.lineTo : context.moveTo).call(context, X(z), Y(Math.min(1, v + data.error_bound))));
        for (let i = points.length - 1; i >= 0; --i) context.lineTo(X(points[i][0]), Y(Math.max(0, points[i][1] - data.error_bound)));
        context.fill();
        context.strokeStyle = colour;
        context.lineWidth = layer === 0 ? 2 : 1;
        context.setLineDash(dashed ? [6, 3] : layer > 0 ? [2, 2] : []);
        context.beginPath();
        points.forEach(([z, v], i) => (i ? context.lineTo : context.moveTo).call(context, X(z), Y(v)));
        context.stroke();
        context.setLineDash([]);
      }
    // Vertices, their counts and the layer starts.
    data.vertices.forEach((v, i) => {
      for (const c of channels) {
        context.fillStyle = channels.length > 1 ? channelColours[c] : px.colour;
        context.beginPath();
        context.arc(X(v.z), Y(v.value[c]), 3, 0, 2 * Math.PI);
        context.fill();
      }
      plotted.push({ map: px.map, x: px.x, y: px.y, level: px.level, index: i, z: v.z, value: v.value, layer: v.layer,
                     screen: [X(v.z), Y(v.value[channels[0]])] });
      if (v.count !== undefined) {
        context.fillStyle = '#bbb';
        context.fillText(String(v.count), X(v.z) + 4, Y(v.value[channels[0]]) - 4);
      }
      if (v.layer > 0 && (i === 0 || data.vertices[i - 1].layer !== v.layer)) {
        context.strokeStyle = '#e599f7';
        context.setLineDash([3, 3]);
        context.beginPath();
        context.moveTo(X(v.z), f.top); context.lineTo(X(v.z), f.top + h);
        context.stroke();
        context.setLineDash([]);
        context.fillStyle = '#e599f7';
        context.fillText(`layer ${v.layer}`, X(v.z) + 3, f.top + 10);
      }
    });
  }
  state.plotted = plotted;
}

function vertexTable() {
  const box = $('vertex-table');
  box.innerHTML = '';
  for (const px of state.pixels) {
    const d = px.data;
    const title = document.createElement('div');
    title.style.color = px.colour;
    title.textContent = `${mapName(px.map)}: pixel ${px.x},${px.y} of level ${px.level}: ${d.vertices.length} vertices ` +
      `in ${d.layers} layer(s); error bound ${Number(d.error_bound.toPrecision(3))}`;
    box.appendChild(title);
    const table = document.createElement('table');
    const head = ['#', 'layer', 'z', ...(d.channels === 3 ? ['R', 'G', 'B'] : ['V'])];
    if (d.vertices.some((v) => v.count !== undefined)) head.push('count');
    table.innerHTML = '<tr>' + head.map((t) => `<th>${t}</th>`).join('') + '</tr>';
    d.vertices.forEach((v, i) => {
      const row = [i, v.layer, v.z, ...v.value];
      if (v.count !== undefined) row.push(v.count);
      const tr = document.createElement('tr');
      tr.innerHTML = row.map((c) => `<td>${typeof c === 'number' && !Number.isInteger(c) ? c.toPrecision(7) : c}</td>`).join('');
      table.appendChild(tr);
    });
    box.appendChild(table);
  }
}

function installPlotHover() {
  const canvas = $('plot');
  canvas.addEventListener('mousemove', (e) => {
    const f = plotFrame;
    const w = canvas.width - f.left - f.right;
    const z = plotRange[0] + (e.offsetX - f.left) / w * (plotRange[1] - plotRange[0]);
    const parts = state.pixels.map((px) => {
      const n = px.data.channels;
      const vs = Array.from({ length: n }, (_, c) => evaluate(px.data, z, c).toFixed(4));
      return `${px.x},${px.y}: V = ${vs.join(', ')}`;
    });
    $('plot-readout').textContent = `z = ${z.toPrecision(6)}  ` + parts.join('  ');
  });
}

// ---------------------------------------------------------------------------
// Controls

function depthRange() {
  const ranges = state.maps.map((m) => m.depth_range);
  return [Math.min(...ranges.map((r) => r[0])), Math.max(...ranges.map((r) => r[1]))];
}

function setSliceFromSlider() {
  const [lo, hi] = depthRange();
  state.sliceZ = Number((lo + (hi - lo) * Number($('depth').value) / 1000).toPrecision(7));
  $('depth-value').value = state.sliceZ;
  changed();
}

/// Soft shadows come progressively: a few rays per receiver, then more.
let softTimer = null;
function scheduleSoftRefine() {
  clearTimeout(softTimer);
  if (state.kind !== 'soft') return;
  state.softSamples = 4;
  softTimer = setTimeout(function refine() {
    if (pending > 0) { softTimer = setTimeout(refine, 200); return; }
    if (state.softSamples < 64) { state.softSamples *= 4; draw(); softTimer = setTimeout(refine, 200); }
  }, 200);
}

function changed() {
  state.scaleMax = 0;
  lastLoaded.clear();
  queue.length = 0;
  for (const [key, tile] of tiles) if (tile.loading) tiles.delete(key);
  scheduleSoftRefine();
  $('depth-box').hidden = !(state.kind === 'slice' || state.kind === 'soft');
  $('soft-box').hidden = state.kind !== 'soft';
  drawScale();
  plot();
  draw();
}

function installControls() {
  $('compare').onchange = (e) => { state.compare = e.target.value; changed(); };
  $('kind').onchange = (e) => { state.kind = e.target.value; changed(); };
  $('channel').onchange = (e) => { state.channel = e.target.value; changed(); };
  $('level').onchange = (e) => { state.level = e.target.value; changed(); };
  $('depth').oninput = setSliceFromSlider;
  $('depth-value').onchange = (e) => { state.sliceZ = Number(e.target.value); changed(); };
  $('radius').onchange = (e) => { state.radius = Number(e.target.value); changed(); };
  $('fit').onclick = fit;
  window.addEventListener('resize', draw);
  installMouse(0);
  installMouse(1);
  installPlotHover();
}

async function start() {
  const reply = await (await fetch('/api/maps')).json();
  state.maps = reply.maps;
  state.ramp = reply.ramp;
  const first = info(0);
  if (state.maps.length > 1) {
    $('compare-box').hidden = false;
    $('compare').options[0].textContent = `A: ${mapName(0)}`;
    $('compare').options[1].textContent = `B: ${mapName(1)}`;
  }
  if (state.maps.some((m) => m.info.channels === 3)) $('channel-box').hidden = false;
  if (!state.maps.some((m) => m.info.max_layers > 1)) $('kind').querySelector('[value=soft]').disabled = true;
  first.levels.forEach((L, l) => {
    const option = document.createElement('option');
    option.value = l;
    option.textContent = `${l} (${L.width} × ${L.height})`;
    $('level').appendChild(option);
  });
  state.radius = state.maps[0].recorded_area_radius || 1;
  $('radius').value = state.radius;
  installControls();
  setSliceFromSlider();
  fit();
}

window.dsmView = {
  state,
  setView,
  fit,
  selectPixel,
  valuesAt,
  idle: () => pending === 0 && !drawScheduled,
  tileCount: () => tiles.size,
};

start().catch((error) => showError(error.message || String(error)));
