// A VRM avatar that speaks: three-vrm loads the model, lipstream streams its expression weights.
//
// The request asks for the rig's controls through a retarget preset (`output.retarget`, `vrm1`
// by default), so every column of a `frames` row is named after a VRM expression: `aa ih ou ee
// oh`, `blink` and the emotions. Each column whose name matches one of the model's expressions
// (case aside, so ARKit-named "perfect sync" custom expressions match `arkit52`) sets that
// expression's weight; three-vrm turns weights into morph target influences in `vrm.update`.
//
// Sound and expressions share one clock, as on the demo page (the protocol, the clock and the
// controls come from its stream.js): the first `audio` or `frames` message fixes t0 on the
// audio clock (plus a short lead), speech chunks play at t0 + their `start`, and every
// animation frame shows the frame for now() - t0.

import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
import { VRMLoaderPlugin, VRMUtils } from "@pixiv/three-vrm";
import {
  clearErrors,
  connect,
  connected,
  ensureAudio,
  errors,
  loadControls,
  now,
  playSpeech,
  send,
  showError,
} from "/demo/stream.js";

const LEAD_S = 0.15;
const DEFAULT_ENGINE = "anime-graph";
const DECIMALS = 2;

const $ = (id) => document.getElementById(id);
const log = { errors, done: [], models: 0 };
let requestNumber = 0;
let current = null;
let vrm = null;
let expressionByName = new Map(); // lower-case name -> the model's expression name

// ---- the scene -------------------------------------------------------------------------

const canvas = $("avatar");
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xdde3ea);
const camera = new THREE.PerspectiveCamera(25, canvas.width / canvas.height, 0.05, 50);
camera.position.set(0, 1.4, 1.6);
scene.add(new THREE.AmbientLight(0xffffff, 1.2));
const light = new THREE.DirectionalLight(0xffffff, 2.0);
light.position.set(1, 2, 3);
scene.add(light);
let renderer = null;
try {
  renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
  renderer.setPixelRatio(window.devicePixelRatio);
} catch (error) {
  // Without WebGL the expressions are still set and read back; only the drawing is missing.
  showError(`no WebGL here, the avatar is not drawn: ${error.message}`);
}
const timer = new THREE.Timer();

function frameHead() {
  const head = vrm.humanoid?.getNormalizedBoneNode("head");
  const target = new THREE.Vector3(0, 1.4, 0);
  if (head) head.getWorldPosition(target);
  camera.position.set(target.x, target.y + 0.02, target.z + 0.9);
  camera.lookAt(target.x, target.y, target.z);
}

// ---- the model -------------------------------------------------------------------------

function loader() {
  const gltfLoader = new GLTFLoader();
  gltfLoader.register((parser) => new VRMLoaderPlugin(parser));
  return gltfLoader;
}

function useModel(gltf, source) {
  const loaded = gltf.userData.vrm;
  if (!loaded) throw new Error(`${source}: not a VRM (no VRMC_vrm or VRM extension)`);
  if (vrm !== null) {
    scene.remove(vrm.scene);
    VRMUtils.deepDispose(vrm.scene);
  }
  VRMUtils.rotateVRM0(loaded); // VRM 0.x faces -Z; 1.0 faces +Z
  vrm = loaded;
  scene.add(vrm.scene);
  expressionByName = new Map(
    (vrm.expressionManager?.expressions ?? []).map((e) => [e.expressionName.toLowerCase(), e.expressionName]),
  );
  frameHead();
  log.models += 1;
  $("speak").disabled = false;
  setStatus(`loaded ${vrm.meta?.name ?? source}: ${expressionByName.size} expressions`);
  showCoverage();
}

async function loadFromUrl(url) {
  useModel(await loader().loadAsync(url), url);
}

async function loadFromFile(file) {
  const buffer = await file.arrayBuffer();
  const gltf = await new Promise((resolve, reject) => loader().parse(buffer, "", resolve, reject));
  useModel(gltf, file.name);
}

// ---- protocol --------------------------------------------------------------------------

function receive(message) {
  if (message.type === "error") {
    // After a fatal error the request's pipelined messages get unknown_request: skip those.
    if (current !== null && message.id === current.id && current.state === "error") return;
    showError(`${message.code}: ${message.message}`);
    if (current !== null && message.fatal && message.id === current.id) finish("error");
    return;
  }
  if (current === null || message.id !== current.id) return; // an abandoned request
  const handlers = { ready: onReady, frames: onFrames, audio: onAudio, done: onDone };
  handlers[message.type]?.(message);
}

async function speak() {
  clearErrors();
  ensureAudio();
  stopCurrent();
  try {
    await connect(receive);
  } catch (error) {
    showError(error.message);
    return;
  }
  const id = `vrm-${++requestNumber}`;
  const start = {
    type: "start",
    id,
    engine: $("engine").value,
    character: $("character").value,
    fps: Number($("fps").value) || 60,
    output: { retarget: $("retarget").value },
  };
  const text = { type: "text", id, text: $("text").value };
  if ($("voice").value.trim()) text.voice = $("voice").value.trim();
  if ($("rate").value) text.rate = Number($("rate").value);
  current = { id, fps: start.fps, channels: [], frames: [], sources: [], t0: null, state: "starting", frozen: false };
  setStatus("waiting for the server");
  send(start);
  send(text);
  send({ type: "end", id });
}

function stopCurrent() {
  if (current === null) return;
  for (const source of current.sources) source.stop();
  if (current.state !== "done" && current.state !== "error" && connected()) {
    send({ type: "cancel", id: current.id });
  }
  current = null;
  vrm?.expressionManager?.resetValues();
}

function onReady(message) {
  current.channels = message.channels;
  current.fps = message.fps;
  current.state = "streaming";
  showCoverage();
}

function fixClock() {
  if (current.t0 === null) current.t0 = now() + LEAD_S;
}

function onFrames(message) {
  fixClock();
  message.data.forEach((row, r) => {
    current.frames[message.first_frame + r] = row;
  });
}

function onAudio(message) {
  fixClock();
  const source = playSpeech(message, current.t0);
  if (source !== null) current.sources.push(source);
}

function onDone(message) {
  log.done.push(message);
  current.frames.length = Math.min(current.frames.length, message.stats.frames);
  finish("done");
}

function finish(state) {
  current.state = state;
  if (state === "error") vrm?.expressionManager?.resetValues();
  setStatus(state === "done" ? "all frames received" : "ended by an error");
}

// ---- expressions -----------------------------------------------------------------------

// The index of the latest frame at or before `index` that has arrived (-1: none yet).
function arrivedAt(index) {
  for (let i = Math.min(index, current.frames.length - 1); i >= 0; i--) {
    if (current.frames[i]) return i;
  }
  return -1;
}

function frameAt(index) {
  const i = arrivedAt(index);
  return i < 0 ? null : current.frames[i];
}

function applyFrame(row) {
  if (row === null || vrm === null || !vrm.expressionManager) return;
  current.channels.forEach((channel, k) => {
    const name = expressionByName.get(channel.toLowerCase());
    if (name !== undefined) vrm.expressionManager.setValue(name, row[k]);
  });
}

function showCoverage() {
  if (vrm === null || current === null || current.channels.length === 0) return;
  const missing = current.channels.filter((c) => !expressionByName.has(c.toLowerCase()));
  $("coverage").textContent =
    `${current.channels.length - missing.length} of ${current.channels.length} channels drive an expression` +
    (missing.length ? `; the model has none named ${missing.join(", ")}` : "");
}

function drawWeights() {
  if (vrm === null || current === null) return;
  const rows = current.channels
    .filter((c) => expressionByName.has(c.toLowerCase()))
    .map((c) => {
      const value = vrm.expressionManager.getValue(expressionByName.get(c.toLowerCase())) ?? 0;
      return `<tr><td>${c}</td><td>${value.toFixed(DECIMALS)}</td>` +
        `<td><div class="bar" style="width:${Math.round(100 * value)}px"></div></td></tr>`;
    });
  $("weights").tBodies[0].innerHTML = rows.join("");
}

function tick(timestamp) {
  timer.update(timestamp);
  const delta = timer.getDelta();
  if (current !== null && current.t0 !== null && !current.frozen) {
    const t = now() - current.t0;
    if (t >= 0) {
      const index = Math.floor(t * current.fps);
      applyFrame(frameAt(index));
      current.shown = { t, index, frame: arrivedAt(index) };
      const end = current.frames.length / current.fps;
      if (current.state === "streaming" || current.state === "done") {
        setStatus(t < end ? `speaking: ${t.toFixed(2)} s` : "done");
      }
      drawWeights();
    }
  }
  if (vrm !== null) vrm.update(delta);
  if (renderer !== null) renderer.render(scene, camera);
  requestAnimationFrame(tick);
}

// ---- status and controls -----------------------------------------------------------------

function setStatus(text) {
  $("status").textContent = text;
}

async function loading(action) {
  clearErrors();
  setStatus("loading the model");
  try {
    await action();
  } catch (error) {
    showError(`cannot load the model: ${error.message ?? error}`);
    setStatus(vrm === null ? "load a VRM model" : "kept the previous model");
  }
}

$("model-form").addEventListener("submit", (event) => {
  event.preventDefault();
  loading(() => loadFromUrl($("model-url").value));
});

$("model-file").addEventListener("change", () => {
  const file = $("model-file").files[0];
  if (file) loading(() => loadFromFile(file));
});

$("text-form").addEventListener("submit", (event) => {
  event.preventDefault();
  speak();
});

const query = new URLSearchParams(location.search);
if (query.has("model")) {
  $("model-url").value = query.get("model");
  loading(() => loadFromUrl(query.get("model")));
}

// For tests and the console: what the page received and what the model shows.
window.lipstreamVrm = {
  log,
  request: () => current,
  frames: () => (current === null ? [] : current.frames.slice()),
  channels: () => (current === null ? [] : current.channels.slice()),
  // Set the expressions for utterance time t (s), as playback would, and apply them to the
  // mesh; stops following playback.
  showAt: (t) => {
    current.frozen = true;
    applyFrame(frameAt(Math.floor(t * current.fps)));
    vrm.update(0);
  },
  expressionWeights: () =>
    Object.fromEntries((vrm?.expressionManager?.expressions ?? []).map((e) => [e.expressionName, e.weight])),
  // Every mesh's morph target influences by target name, as three.js will draw them.
  morphInfluences: () => {
    const meshes = {};
    vrm?.scene.traverse((object) => {
      if (!object.morphTargetInfluences || !object.morphTargetDictionary) return;
      const influences = {};
      for (const [target, index] of Object.entries(object.morphTargetDictionary)) {
        influences[target] = object.morphTargetInfluences[index];
      }
      meshes[object.name] = influences;
    });
    return meshes;
  },
  webgl: () => renderer !== null,
};

loadControls(DEFAULT_ENGINE);
requestAnimationFrame(tick);
