// The studio: the phoneme-Isomap editor of expressive-dp (Deng & Neumann 2008, §IV–V).
//
// The map is drawn as the paper draws it: every frame of the phoneme's cluster is a Gaussian
// kernel splatted into an accumulation buffer in its emotion's colour, so dense regions read
// as solid colour and sparse ones fade; the motion nodes are trajectories through it. All of
// it comes from the phoneme-map routes (docs/reference/server.md): the map, a pick (the
// barycentric blend of the triangle under the pointer, shown as the face), a node's clip,
// the contamination file and the candidates of a constrained phoneme. A sentence is turned
// into the phoneme spans constraints are numbered by (phoneme-maps/utterance), synthesized
// with POST /v1/synthesize, and its chosen nodes read from the answer's stats.

import { Face } from "./face.js";
import { parseLab, parseTextGrid } from "./phones.js";
import { Plot } from "./plot.js";
import { audioRunning, clearErrors, ensureAudio, errors, now, pcm16ToFloat, playAt, showError } from "./stream.js";

const ENGINE = "expressive-dp";
const FPS = 60;
const KERNEL_PX = 5;
const NEAR_PX = 9;
const PLOTTED = ["jawOpen", "mouthClose", "mouthFunnel", "mouthPucker"];
const EMOTION_COLOURS = {
  neutral: [70, 110, 160],
  happy: [230, 140, 20],
  angry: [200, 40, 40],
  sad: [60, 60, 200],
};
const PAPER = [251, 250, 247];

const $ = (id) => document.getElementById(id);
const face = new Face($("face"));
const plot = new Plot($("plot"));
const canvas = $("map");
const context = canvas.getContext("2d");
const token = new URLSearchParams(location.search).get("access_token");

const state = {
  character: null,
  summary: [],
  phoneme: null,
  map: null,
  bounds: null,
  selectedNode: null,
  undo: [],
  sentence: null, // {items, speech, frames, channels, path}
  sentenceIndex: null,
  candidates: null,
  constraints: {},
  lasso: null,
};
const log = { errors, picks: 0, syntheses: 0, clips: 0, paths: [] };
// Where a node's middle frame is drawn, in client coordinates (for tests and the console).
function locate(id) {
  const node = nodeById(id);
  if (node === null) return null;
  const points = trajectory(node);
  const [px, py] = points[Math.floor(points.length / 2)];
  const rect = canvas.getBoundingClientRect();
  return { x: rect.left + (px * rect.width) / canvas.width, y: rect.top + (py * rect.height) / canvas.height };
}
window.lipstreamStudio = { state, log, locate };

// ---- server --------------------------------------------------------------------------

async function api(path, body = undefined) {
  const headers = { accept: "application/json" };
  if (token) headers.authorization = `Bearer ${token}`;
  const init = { headers };
  if (body !== undefined) {
    init.method = "POST";
    init.body = JSON.stringify(body);
    headers["content-type"] = "application/json";
  }
  const answer = await fetch(path, init);
  const parsed = await answer.json().catch(() => null);
  if (!answer.ok) {
    const error = parsed?.error;
    throw new Error(error ? `${error.code}: ${error.message}` : `${path}: HTTP ${answer.status}`);
  }
  return parsed;
}

const characterPath = (tail) => `/v1/characters/${encodeURIComponent(state.character)}/${tail}`;

function report(error) {
  showError(error.message);
}

// ---- phonemes and their maps ----------------------------------------------------------

async function loadSummary() {
  const answer = await api(characterPath("phoneme-maps"));
  state.summary = answer.phonemes;
  const body = $("phonemes").querySelector("tbody");
  body.replaceChildren();
  for (const row of state.summary) {
    const line = document.createElement("tr");
    line.dataset.phoneme = row.phoneme;
    for (const value of [row.phoneme, row.frame_count, row.node_count, row.clean_node_count]) {
      const cell = document.createElement("td");
      cell.textContent = value;
      line.appendChild(cell);
    }
    line.classList.toggle("chosen", row.phoneme === state.phoneme);
    line.addEventListener("click", () => showPhoneme(row.phoneme).catch(report));
    body.appendChild(line);
  }
}

async function showPhoneme(phoneme) {
  state.map = await api(characterPath(`phoneme-maps/${encodeURIComponent(phoneme)}`));
  state.phoneme = phoneme;
  state.bounds = boundsOf(state.map.frames);
  for (const line of $("phonemes").querySelectorAll("tr[data-phoneme]")) {
    line.classList.toggle("chosen", line.dataset.phoneme === phoneme);
  }
  const clean = state.map.nodes.filter((node) => !node.contaminated).length;
  $("map-title").textContent =
    `${phoneme}: ${state.map.frames.x.length} frames, ${state.map.nodes.length} nodes (${clean} clean)`;
  drawMap();
}

function boundsOf(frames) {
  const xs = frames.x;
  const ys = frames.y;
  let [left, right, top, bottom] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  const padX = 0.06 * (right - left || 1);
  const padY = 0.06 * (bottom - top || 1);
  return { left: left - padX, right: right + padX, top: top - padY, bottom: bottom + padY };
}

function toScreen(x, y) {
  const b = state.bounds;
  return [((x - b.left) / (b.right - b.left)) * canvas.width, ((y - b.top) / (b.bottom - b.top)) * canvas.height];
}

function toMap(px, py) {
  const b = state.bounds;
  return [b.left + (px / canvas.width) * (b.right - b.left), b.top + (py / canvas.height) * (b.bottom - b.top)];
}

function eventPoint(event) {
  const rect = canvas.getBoundingClientRect();
  return [((event.clientX - rect.left) * canvas.width) / rect.width, ((event.clientY - rect.top) * canvas.height) / rect.height];
}

// ---- drawing -------------------------------------------------------------------------

function drawMap() {
  const { width, height } = canvas;
  const map = state.map;
  if (map === null) return;
  const weight = new Float32Array(width * height);
  const colour = new Float32Array(3 * width * height);
  const emotionOfFrame = map.frames.node.map((node) => nodeById(node)?.emotion ?? "neutral");
  const reach = 3 * KERNEL_PX;
  for (let i = 0; i < map.frames.x.length; i++) {
    const [cx, cy] = toScreen(map.frames.x[i], map.frames.y[i]);
    const rgb = EMOTION_COLOURS[emotionOfFrame[i]] ?? EMOTION_COLOURS.neutral;
    for (let py = Math.max(0, Math.floor(cy - reach)); py <= Math.min(height - 1, cy + reach); py++) {
      for (let px = Math.max(0, Math.floor(cx - reach)); px <= Math.min(width - 1, cx + reach); px++) {
        const d2 = (px - cx) ** 2 + (py - cy) ** 2;
        const w = Math.exp(-d2 / (2 * KERNEL_PX * KERNEL_PX));
        const at = py * width + px;
        weight[at] += w;
        colour[3 * at] += w * rgb[0];
        colour[3 * at + 1] += w * rgb[1];
        colour[3 * at + 2] += w * rgb[2];
      }
    }
  }
  const image = context.createImageData(width, height);
  for (let at = 0; at < width * height; at++) {
    const w = weight[at];
    const alpha = 1 - Math.exp(-1.5 * w);
    for (let c = 0; c < 3; c++) {
      const ink = w > 0 ? colour[3 * at + c] / w : PAPER[c];
      image.data[4 * at + c] = PAPER[c] + alpha * (ink - PAPER[c]);
    }
    image.data[4 * at + 3] = 255;
  }
  context.putImageData(image, 0, 0);
  const candidates = state.candidates?.phoneme === state.phoneme ? state.candidates : null;
  const contextCorrect = new Set(candidates?.context_correct ?? []);
  const chosen = chosenNode();
  for (const node of map.nodes) {
    const points = trajectory(node);
    context.beginPath();
    points.forEach(([x, y], k) => (k === 0 ? context.moveTo(x, y) : context.lineTo(x, y)));
    context.setLineDash(node.contaminated ? [4, 4] : []);
    context.strokeStyle = node.contaminated ? "#999" : "#222";
    context.lineWidth = node.id === state.selectedNode ? 3 : contextCorrect.has(node.id) ? 2 : 0.7;
    if (node.id === chosen) context.strokeStyle = "#e8590c";
    context.stroke();
  }
  context.setLineDash([]);
  for (const candidate of candidates?.time_correct ?? []) {
    const [x, y] = toScreen(candidate.x, candidate.y);
    context.beginPath();
    context.arc(x, y, 4, 0, 2 * Math.PI);
    context.strokeStyle = contextCorrect.has(candidate.node) ? "#2f9e44" : "#555";
    context.lineWidth = 1.5;
    context.stroke();
  }
  if (state.lasso !== null && state.lasso.length > 1) {
    context.beginPath();
    state.lasso.forEach(([x, y], k) => (k === 0 ? context.moveTo(x, y) : context.lineTo(x, y)));
    context.closePath();
    context.strokeStyle = "#9c36b5";
    context.lineWidth = 1.5;
    context.stroke();
  }
  $("map-legend").replaceChildren(
    ...Object.entries(EMOTION_COLOURS).map(([name, rgb]) => {
      const key = document.createElement("span");
      key.textContent = name;
      key.style.color = `rgb(${rgb.join(",")})`;
      return key;
    }),
  );
}

function nodeById(id) {
  return state.map?.nodes.find((node) => node.id === id) ?? null;
}

function trajectory(node) {
  const points = [];
  for (let k = node.first_frame; k < node.first_frame + node.frame_count; k++) {
    points.push(toScreen(state.map.frames.x[k], state.map.frames.y[k]));
  }
  return points;
}

function nearestNode(px, py) {
  let best = null;
  let bestDistance = NEAR_PX;
  for (const node of state.map?.nodes ?? []) {
    for (const [x, y] of trajectory(node)) {
      const distance = Math.hypot(x - px, y - py);
      if (distance < bestDistance) [best, bestDistance] = [node, distance];
    }
  }
  return best;
}

// ---- preview -------------------------------------------------------------------------

let picking = false;
let pendingPick = null;

async function pick(px, py) {
  if (state.map === null) return;
  if (picking) {
    pendingPick = [px, py];
    return;
  }
  picking = true;
  try {
    const [x, y] = toMap(px, py);
    const picked = await api(characterPath(`phoneme-maps/${encodeURIComponent(state.phoneme)}/pick`), { x, y });
    face.apply(Object.fromEntries(picked.channels.map((name, k) => [name, picked.frame[k]])));
    log.picks += 1;
    const weights = picked.weights.map((w) => w.toFixed(2)).join(", ");
    $("blend-info").textContent = `nodes ${picked.nodes.join(", ")} (${weights})${picked.inside ? "" : ", nearest"}`;
  } catch (error) {
    report(error);
  } finally {
    picking = false;
  }
  if (pendingPick !== null) {
    const next = pendingPick;
    pendingPick = null;
    await pick(...next);
  }
}

let playing = null;

async function selectNode(node) {
  state.selectedNode = node.id;
  $("mark-node").disabled = node.contaminated;
  $("restore-node").disabled = !node.contaminated;
  $("pin").disabled = state.sentenceIndex === null;
  drawMap();
  const clip = await api(characterPath(`nodes/${node.id}`));
  log.clips += 1;
  $("node-info").textContent =
    `${clip.id}: ${clip.previous}-${clip.phoneme}+${clip.next}, ${clip.emotion}, ${clip.frames.length} frames` +
    (clip.contaminated ? ", contaminated" : "");
  play(clip.frames, clip.fps, clip.channels, null);
}

function play(frames, fps, channels, speech) {
  if (playing !== null) cancelAnimationFrame(playing.handle);
  let t0 = now() + 0.1;
  if (speech && audioRunning()) {
    const samples = pcm16ToFloat(speech.pcm16);
    const context = ensureAudio();
    const buffer = context.createBuffer(1, samples.length, speech.sample_rate);
    buffer.copyToChannel(samples, 0);
    playAt(buffer, t0);
  } else {
    t0 = now();
  }
  const chosen = PLOTTED.filter((name) => channels.includes(name));
  const step = () => {
    const elapsed = now() - t0;
    const index = Math.min(frames.length - 1, Math.max(0, Math.floor(elapsed * fps)));
    face.apply(Object.fromEntries(channels.map((name, k) => [name, frames[index][k]])));
    plot.draw(frames, fps, channels, chosen, elapsed);
    if (elapsed * fps < frames.length) playing = { handle: requestAnimationFrame(step) };
    else {
      playing = null;
      $("status").textContent = "idle";
    }
  };
  $("status").textContent = "playing";
  playing = { handle: requestAnimationFrame(step) };
}

// ---- cleaning ------------------------------------------------------------------------

async function changeContamination(mark, restore, undoable = true) {
  const answer = await api(characterPath("contamination"), { mark, restore });
  if (undoable) state.undo.push({ mark: restore, restore: mark });
  $("undo").disabled = state.undo.length === 0;
  $("undo-count").textContent = state.undo.length ? `${state.undo.length} to undo` : "nothing to undo";
  await Promise.all([loadSummary(), showPhoneme(state.phoneme)]);
  const node = nodeById(state.selectedNode);
  if (node !== null) {
    $("mark-node").disabled = node.contaminated;
    $("restore-node").disabled = !node.contaminated;
  }
  if (state.sentence !== null) await synthesize();
  return answer;
}

function inside(polygon, [x, y]) {
  let within = false;
  for (let i = 0, j = polygon.length - 1; i < polygon.length; j = i++) {
    const [xi, yi] = polygon[i];
    const [xj, yj] = polygon[j];
    if (yi > y !== yj > y && x < ((xj - xi) * (y - yi)) / (yj - yi) + xi) within = !within;
  }
  return within;
}

function lassoed(polygon) {
  const touched = [];
  for (const node of state.map.nodes) {
    if (!node.contaminated && trajectory(node).some((point) => inside(polygon, point))) touched.push(node.id);
  }
  return touched;
}

// ---- sentence and constraints ---------------------------------------------------------

function chosenNode() {
  if (state.sentence === null || state.sentenceIndex === null) return null;
  return state.sentence.path[state.sentenceIndex] ?? null;
}

async function loadSentence(body) {
  const answer = await api(characterPath("phoneme-maps/utterance"), body);
  await useItems(answer.items, answer.speech ?? null);
}

async function useItems(items, speech) {
  state.sentence = { items, speech, frames: [], channels: [], path: [] };
  state.constraints = {};
  state.sentenceIndex = null;
  state.candidates = null;
  await synthesize();
}

async function synthesize() {
  const sentence = state.sentence;
  const options = Object.keys(state.constraints).length ? { constraints: state.constraints } : {};
  const answer = await api("/v1/synthesize", {
    engine: ENGINE,
    character: state.character,
    fps: FPS,
    items: sentence.items,
    options,
  });
  sentence.frames = answer.data;
  sentence.channels = answer.channels;
  sentence.path = String(answer.stats.engine.nodes ?? "")
    .split(/\s+/)
    .filter(Boolean)
    .map(Number);
  log.syntheses += 1;
  log.paths.push([...sentence.path]);
  drawSentence();
  drawConstraints();
  $("play").disabled = false;
  drawMap();
}

function drawSentence() {
  const strip = $("sentence-phonemes");
  strip.replaceChildren();
  state.sentence.items.forEach((item, index) => {
    const chip = document.createElement("button");
    chip.type = "button";
    chip.dataset.index = index;
    const node = state.sentence.path[index];
    chip.textContent = `${index} ${item.phoneme}` + (node >= 0 ? ` · ${node}` : "");
    chip.classList.toggle("chosen", index === state.sentenceIndex);
    chip.classList.toggle("pinned", String(index) in state.constraints);
    chip.disabled = item.phoneme === "sil";
    chip.addEventListener("click", () => choosePhonemeOfSentence(index).catch(report));
    strip.appendChild(chip);
  });
}

async function choosePhonemeOfSentence(index) {
  const item = state.sentence.items[index];
  state.sentenceIndex = index;
  const time = (item.start + item.end) / 2;
  state.candidates = await api(characterPath("phoneme-maps/candidates"), { items: state.sentence.items, index, time });
  const label = state.summary.find((row) => row.phoneme === state.candidates.phoneme)?.phoneme ?? item.phoneme;
  await showPhoneme(label);
  $("pin").disabled = state.selectedNode === null;
  drawSentence();
}

function drawConstraints() {
  const list = $("constraints");
  list.replaceChildren();
  for (const [index, node] of Object.entries(state.constraints)) {
    const line = document.createElement("li");
    const phoneme = state.sentence.items[Number(index)]?.phoneme ?? "?";
    const followed = state.sentence.path[Number(index)] === node ? "" : " (not followed!)";
    line.textContent = `phoneme ${index} (${phoneme}) → node ${node}${followed} `;
    const remove = document.createElement("button");
    remove.type = "button";
    remove.textContent = "remove";
    remove.addEventListener("click", async () => {
      delete state.constraints[index];
      await synthesize().catch(report);
    });
    line.appendChild(remove);
    list.appendChild(line);
  }
  $("export").value = JSON.stringify({ constraints: state.constraints });
}

// ---- events --------------------------------------------------------------------------

canvas.addEventListener("mousemove", (event) => {
  const point = eventPoint(event);
  if (state.lasso !== null) {
    state.lasso.push(point);
    drawMap();
    return;
  }
  pick(...point);
});

canvas.addEventListener("mousedown", (event) => {
  if ($("lasso").checked) state.lasso = [eventPoint(event)];
});

canvas.addEventListener("mouseup", async (event) => {
  if (state.lasso !== null) {
    const polygon = state.lasso;
    state.lasso = null;
    const marked = polygon.length > 2 ? lassoed(polygon) : [];
    drawMap();
    if (marked.length) await changeContamination(marked, []).catch(report);
    return;
  }
  const [px, py] = eventPoint(event);
  await pick(px, py);
  const node = nearestNode(px, py);
  if (node !== null) await selectNode(node).catch(report);
});

$("mark-node").addEventListener("click", () => changeContamination([state.selectedNode], []).catch(report));
$("restore-node").addEventListener("click", () => changeContamination([], [state.selectedNode]).catch(report));
$("undo").addEventListener("click", async () => {
  const last = state.undo.pop();
  if (last) await changeContamination(last.mark, last.restore, false).catch(report);
});

$("pin").addEventListener("click", async () => {
  if (state.sentenceIndex === null || state.selectedNode === null) return;
  state.constraints[String(state.sentenceIndex)] = state.selectedNode;
  await synthesize().catch(report);
});

$("play").addEventListener("click", () => {
  ensureAudio();
  const sentence = state.sentence;
  play(sentence.frames, FPS, sentence.channels, sentence.speech);
});

$("sentence-form").addEventListener("submit", (event) => {
  event.preventDefault();
  clearErrors();
  ensureAudio();
  loadSentence({ text: $("sentence").value, lang: $("lang").value || undefined }).catch(report);
});

$("sentence-file").addEventListener("change", async () => {
  const file = $("sentence-file").files[0];
  if (!file) return;
  clearErrors();
  const text = await file.text();
  try {
    if (/\.textgrid$/i.test(file.name)) await useItems(parseTextGrid(text), null);
    else if (/\.lab$/i.test(file.name)) await useItems(parseLab(text), null);
    else await loadSentence({ words: { timings: text, format: "auto" } });
  } catch (error) {
    report(error);
  }
});

$("character").addEventListener("change", () => start($("character").value).catch(report));

async function start(character) {
  state.character = character;
  state.sentence = null;
  state.undo = [];
  await loadSummary();
  const first = state.summary.find((row) => row.phoneme !== "sil") ?? state.summary[0];
  if (first) await showPhoneme(first.phoneme);
}

async function main() {
  try {
    const listed = await api("/v1/characters");
    const characters = listed.characters.filter((c) => c.engines.includes(ENGINE)).map((c) => c.name);
    if (characters.length === 0) {
      $("no-model").hidden = false;
      $("no-model").textContent =
        "This server holds no expressive-dp model, so there is nothing to edit. Train one " +
        "(lipstream train --engine expressive-dp) and serve it beside the others.";
      $("studio").hidden = true;
    } else {
      for (const name of characters) $("character").add(new Option(name));
      await start(characters[0]);
    }
  } catch (error) {
    report(error);
  }
  document.body.dataset.ready = "true";
}

main();
