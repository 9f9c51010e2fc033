// The demo page: controls, requests over the lipstream protocol, the face and the readouts.
//
// Sound and face share one clock (stream.js): the first `audio` or `frames` message of a
// request fixes t0 on it (plus a short lead); speech chunks are scheduled at t0 + their
// `start`, an uploaded WAV (beside phones or a TTS's timing file) at t0, and every animation
// frame shows the frame for now() - t0.
//
// A request ends with the face at rest. After `done`, playback reaches the last frame, which
// the server makes the character's rest pose, and the face stays there. An error leaves no
// such frame: the face eases at once from what it shows to the page's neutral face (every
// channel 0, as drawn before any request) over RETURN_S with a smoothstep.

import { Face } from "./face.js";
import { parseLab, parseTextGrid } from "./phones.js";
import { Plot } from "./plot.js";
import {
  audioRunning,
  clearErrors,
  clockName,
  connect,
  connected,
  ensureAudio,
  errors,
  getJson,
  loadControls,
  now,
  playAt,
  playSpeech,
  send,
  showError,
} from "./stream.js";

const LEAD_S = 0.15;
const AUDIO_CHUNK_S = 0.25;
const PHONEMES_PER_MESSAGE = 256;
const DEFAULT_PLOTTED = ["jawOpen", "mouthClose", "mouthFunnel", "mouthSmileLeft"];
const DEFAULT_ENGINE = "anime-graph";
const DEFAULT_LANG = "en-us";
const RETURN_S = 0.15;
const DECIMALS = 2;

const $ = (id) => document.getElementById(id);
const face = new Face($("face"));
const plot = new Plot($("plot"));
let requestNumber = 0;
let current = null;
const log = { errors, done: [] };

// ---- protocol ------------------------------------------------------------------------

function receive(message) {
  if (message.type === "error") {
    // After a fatal error, the server answers the request's pipelined messages with
    // unknown_request: the first error said it all.
    const over = current !== null && message.id === current.id && current.state === "error";
    if (!over && (message.id === null || current === null || message.id === current.id)) {
      showError(`${message.code}: ${message.message}`);
      if (current !== null && message.fatal && message.id === current.id) finish("error");
    }
    return;
  }
  if (current === null || message.id !== current.id) return; // an abandoned request
  const handlers = { ready: onReady, frames: onFrames, audio: onAudio, done: onDone };
  handlers[message.type]?.(message);
}

// ---- a request ------------------------------------------------------------------------

async function startRequest(input) {
  clearErrors();
  ensureAudio();
  stopCurrent();
  try {
    await connect(receive);
  } catch (error) {
    showError(error.message);
    return;
  }
  const id = `demo-${++requestNumber}`;
  const fps = Number($("fps").value) || 60;
  const start = { type: "start", id, engine: $("engine").value, character: $("character").value, fps };
  if ($("emotion").value) start.emotion = $("emotion").value;
  if ($("budget").value) start.latency_budget_ms = Number($("budget").value);
  current = {
    id,
    fps,
    channels: [],
    frames: [],
    sources: [],
    t0: null,
    sentAt: performance.now(),
    firstFrameMs: null,
    localAudio: input.audioBuffer ?? null,
    state: "starting",
    frozen: false,
  };
  setStatus("waiting for the server");
  $("latency").textContent = "–";
  $("rung").textContent = "–";
  $("stats").textContent = "–";
  send(start);
  input.send(id);
  send({ type: "end", id });
}

function stopCurrent() {
  if (current === null) return;
  for (const source of current.sources) {
    try {
      source.stop();
    } catch (_) {
      // not started yet
    }
  }
  if (current.state !== "done" && current.state !== "error" && connected()) {
    send({ type: "cancel", id: current.id });
  }
  current = null;
}

function onReady(message) {
  current.channels = message.channels;
  current.fps = message.fps;
  current.state = "streaming";
  $("rung").textContent = `${message.fidelity} (lookahead ${message.lookahead_ms.toFixed(1)} ms)`;
  fillPlotChannels(message.channels);
}

function fixClock() {
  if (current.t0 !== null) return;
  current.t0 = now() + LEAD_S;
  $("clock").textContent = clockName();
  if (current.localAudio !== null && audioRunning()) {
    current.sources.push(playAt(current.localAudio, current.t0));
  }
}

function onFrames(message) {
  if (current.firstFrameMs === null) {
    current.firstFrameMs = performance.now() - current.sentAt;
    $("latency").textContent = `${current.firstFrameMs.toFixed(0)} ms (measured by the page)`;
  }
  fixClock();
  message.data.forEach((row, r) => {
    current.frames[message.first_frame + r] = row;
  });
  drawPlot();
}

function onAudio(message) {
  fixClock();
  const source = playSpeech(message, current.t0);
  if (source !== null) current.sources.push(source);
}

function onDone(message) {
  log.done.push(message);
  const stats = message.stats;
  if (stats.first_frame_latency_ms != null) {
    $("latency").textContent =
      `${(current.firstFrameMs ?? 0).toFixed(0)} ms at the page, ` +
      `${stats.first_frame_latency_ms.toFixed(0)} ms at the server`;
  }
  $("stats").textContent = JSON.stringify({ reason: message.reason, ...stats }, rounded, 2);
  current.frames.length = Math.min(current.frames.length, stats.frames);
  finish("done");
}

// Numbers with at most DECIMALS decimals, for the readouts.
function rounded(_key, value) {
  return typeof value === "number" && !Number.isInteger(value)
    ? Number(value.toFixed(DECIMALS))
    : value;
}

function finish(state) {
  current.state = state;
  if (state === "error") returnToRest();
  setStatus(state === "done" ? "all frames received" : "ended by an error");
  drawPlot();
}

// ---- inputs ---------------------------------------------------------------------------

function textInput() {
  const message = { type: "text", text: $("text").value };
  if ($("lang").value) message.lang = $("lang").value;
  if ($("voice").value) message.voice = $("voice").value;
  if ($("rate").value) message.rate = Number($("rate").value);
  return { send: (id) => send({ ...message, id }) };
}

// The WAV chosen in the file input `inputId`, decoded, or null.
async function chosenAudio(inputId) {
  const wavFile = $(inputId).files[0];
  return wavFile ? ensureAudio().decodeAudioData(await wavFile.arrayBuffer()) : null;
}

async function fileInput() {
  const phonesFile = $("phones-file").files[0];
  if (!phonesFile) throw new Error("choose a .TextGrid or .lab file first");
  const text = await phonesFile.text();
  const items = /\.lab$/i.test(phonesFile.name) ? parseLab(text) : parseTextGrid(text);
  const audioBuffer = await chosenAudio("wav-file");
  return {
    audioBuffer,
    send: (id) => {
      if (audioBuffer !== null) sendAudio(id, audioBuffer);
      for (let i = 0; i < items.length; i += PHONEMES_PER_MESSAGE) {
        send({ type: "phonemes", id, items: items.slice(i, i + PHONEMES_PER_MESSAGE) });
      }
    },
  };
}

// A TTS's timing file as one `words` message: its JSON value, or JSON lines as text (the
// server reads both, and says what is wrong with either), after the audio's chunks.
async function timingInput() {
  const timingFile = $("timing-file").files[0];
  if (!timingFile) throw new Error("choose a timing file first");
  const text = await timingFile.text();
  let timings;
  try {
    timings = JSON.parse(text);
  } catch (_) {
    timings = text; // JSON lines (Polly's speech marks), or not JSON at all
  }
  const format = $("timing-format").value;
  const audioBuffer = await chosenAudio("timing-wav-file");
  return {
    audioBuffer,
    send: (id) => {
      if (audioBuffer !== null) sendAudio(id, audioBuffer);
      send({ type: "words", id, timings, format });
    },
  };
}

function sendAudio(id, buffer) {
  const samples = buffer.getChannelData(0);
  const step = Math.round(buffer.sampleRate * AUDIO_CHUNK_S);
  for (let offset = 0; offset < samples.length; offset += step) {
    const chunk = samples.subarray(offset, offset + step);
    send({ type: "audio", id, sample_rate: buffer.sampleRate, pcm16: floatToPcm16(chunk) });
  }
}

function floatToPcm16(samples) {
  const view = new DataView(new ArrayBuffer(samples.length * 2));
  samples.forEach((value, i) => {
    view.setInt16(2 * i, Math.max(-32768, Math.min(32767, Math.round(value * 32767))), true);
  });
  let text = "";
  const bytes = new Uint8Array(view.buffer);
  for (let i = 0; i < bytes.length; i += 0x8000) {
    text += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
  }
  return btoa(text);
}

// ---- drawing --------------------------------------------------------------------------

// The latest frame at or before `index` that has arrived.
function frameAt(index) {
  if (current === null) return null;
  for (let i = Math.min(index, current.frames.length - 1); i >= 0; i--) {
    if (current.frames[i]) return current.frames[i];
  }
  return null;
}

function showFrame(row) {
  if (row === null) return;
  const values = {};
  current.channels.forEach((name, k) => {
    values[name] = row[k];
  });
  face.apply(values);
}

// Ease the face from what it shows now to the neutral face (once per request).
function returnToRest() {
  if (current.returning) return;
  current.returning = { from: { ...face.values }, at: now() };
}

function showReturn() {
  const { from, at } = current.returning;
  const u = Math.max(0, Math.min(1, (now() - at) / RETURN_S));
  const keep = 1 - u * u * (3 - 2 * u);
  const values = {};
  if (keep > 0) for (const name of Object.keys(from)) values[name] = from[name] * keep;
  face.apply(values);
}

function playbackTime() {
  return current === null || current.t0 === null ? null : now() - current.t0;
}

function tick() {
  const t = playbackTime();
  if (current !== null && !current.frozen && current.returning) {
    showReturn();
  } else if (t !== null && t >= 0 && !current.frozen) {
    const end = current.frames.length / current.fps;
    showFrame(frameAt(Math.floor(t * current.fps)));
    if (current.state === "streaming" || current.state === "done") {
      setStatus(t < end ? `speaking: ${t.toFixed(2)} s` : "done");
    }
    drawPlot();
  }
  requestAnimationFrame(tick);
}

function drawPlot() {
  if (current === null) return;
  const chosen = [...$("plot-channels").selectedOptions].map((o) => o.value);
  plot.draw(current.frames, current.fps, current.channels, chosen, playbackTime());
}

function fillPlotChannels(channels) {
  const select = $("plot-channels");
  const before = new Set([...select.selectedOptions].map((o) => o.value));
  select.replaceChildren();
  for (const name of channels) {
    const option = new Option(name, name);
    option.selected = before.size ? before.has(name) : DEFAULT_PLOTTED.includes(name);
    select.add(option);
  }
}

// ---- status and controls --------------------------------------------------------------

function setStatus(text) {
  $("status").textContent = text;
}

// The languages and voice variants espeak-ng has, for the text's language and voice.
async function loadLanguages() {
  let listed;
  try {
    listed = await getJson("/v1/languages");
  } catch (error) {
    showError(`cannot list the languages: ${error.message}`);
    return;
  }
  const languages = $("lang");
  languages.replaceChildren();
  for (const language of listed.languages) {
    languages.add(new Option(`${language.name} (${language.lang})`, language.lang));
  }
  languages.value = DEFAULT_LANG;
  const voices = $("voice");
  for (const variant of listed.variants) voices.add(new Option(variant));
}

$("text-form").addEventListener("submit", (event) => {
  event.preventDefault();
  startRequest(textInput());
});

// A form whose input is read from files (`makeInput`), which may fail before any request.
function playsFiles(formId, makeInput) {
  $(formId).addEventListener("submit", async (event) => {
    event.preventDefault();
    try {
      await startRequest(await makeInput());
    } catch (error) {
      showError(error.message);
    }
  });
}

playsFiles("file-form", fileInput);
playsFiles("timing-form", timingInput);

$("plot-channels").addEventListener("change", drawPlot);

// For tests and the console: what the page received and drew.
window.lipstreamDemo = {
  face,
  log,
  request: () => current,
  frames: () => (current === null ? [] : current.frames.slice()),
  channels: () => (current === null ? [] : current.channels.slice()),
  // Draw the face for utterance time t (s), as playback would at that moment.
  // Stops following playback.
  showAt: (t) => {
    current.frozen = true;
    showFrame(frameAt(Math.floor(t * current.fps)));
  },
  mouthOpening: () => face.mouthOpening(),
  faceValues: () => ({ ...face.values }),
};

loadControls(DEFAULT_ENGINE, loadLanguages);
requestAnimationFrame(tick);
