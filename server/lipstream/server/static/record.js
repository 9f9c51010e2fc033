// The recording page: a visitor's face and voice in, a character of their own out.
//
// A session is created with POST /v1/recordings (the character's name, and the visitor's
// own sentences if they gave any); the page prompts each sentence in turn. A take opens the
// camera and microphone (getUserMedia) unless a check already has them open, shows them
// live (the preview and an RMS level meter from an AnalyserNode), records both with
// MediaRecorder, closes them when it stops, and uploads the recording with an
// XMLHttpRequest (whose upload events give the progress bar) to
// PUT /v1/recordings/{session}/takes/{index}; recording a sentence again replaces its
// take. POST .../train starts the job; GET /v1/recordings/{session} is polled with
// backoff (a short delay while something changes, growing to MAX_POLL_MS while nothing
// does) for each take's status and the job's step and progress. When the job is done the
// page links to the demo page with `?character=<name>`. Every failure is shown in words:
// the device errors by their DOMException name, the server's by its coded error.

import { clearErrors, errors, keepToken, showError } from "./stream.js";

const MIME_TYPES = ["video/webm;codecs=vp8,opus", "video/webm;codecs=vp9,opus", "video/webm", "video/mp4"];
const TIMESLICE_MS = 250;
const MAX_TAKE_S = 30;
const FIRST_POLL_MS = 400;
const MAX_POLL_MS = 4000;
const POLL_GROWTH = 1.5;
const LEVEL_GAIN = 2.5; // speech RMS is about 0.05 to 0.3 of full scale: loud speech near the top
const SIZE_MARGIN = 0.95; // a take stops this close to the server's size limit
const FINISHED = ["done", "failed"];
const STEPS = ["queued", "capturing", "aligning", "training", "loading", "done"];
const REASONS = {
  no_face: "no face found in the video",
  several_faces: "more than one face in the video",
  tracking_gap: "the face was lost for too long",
  no_speech: "no speech heard",
  not_speech: "no speech heard",
  transcript_mismatch: "the speech does not match the sentence",
  alignment_failed: "the speech could not be aligned to the sentence",
  corrupt_video: "the recording could not be decoded",
  no_video_track: "the recording has no picture",
  no_audio_track: "the recording has no sound",
};

const $ = (id) => document.getElementById(id);
const token = new URLSearchParams(location.search).get("access_token");

const state = {
  session: null,
  name: null,
  sentences: [], // [{index, text}]
  limits: null,
  current: 0, // position in `sentences`
  takes: new Map(), // sentence index -> the server's take {index, bytes, status, error}
  uploadErrors: new Map(), // sentence index -> why its upload failed
  job: null,
  lastStep: null, // the job's last state before it ended, to show where it failed
  stream: null,
  meter: null, // {context, analyser, samples}
  take: null, // the take being recorded
  uploading: false,
  training: false,
};
const log = { errors, recorded: 0, uploads: [], polls: 0, peakLevel: 0 };
window.lipstreamRecord = { state, log };

// ---- server --------------------------------------------------------------------------

// The URL with the page's access token, for links to the other pages.
function withToken(url) {
  if (!token) return url;
  const joined = new URL(url, location.href);
  joined.searchParams.set("access_token", token);
  return joined.pathname + joined.search;
}

function headers(extra = {}) {
  return token ? { ...extra, authorization: `Bearer ${token}` } : extra;
}

// The server's coded error as words, or the HTTP status when it sent none.
function described(status, parsed, what) {
  const error = parsed?.error;
  return error ? `${error.code}: ${error.message}` : `${what}: HTTP ${status}`;
}

async function api(method, path, body = undefined) {
  const init = { method, headers: headers({ accept: "application/json" }) };
  if (body !== undefined) {
    init.body = JSON.stringify(body);
    init.headers["content-type"] = "application/json";
  }
  let answer;
  try {
    answer = await fetch(path, init);
  } catch (_) {
    throw Object.assign(new Error(`cannot reach the server (${method} ${path})`), { status: 0 });
  }
  const parsed = await answer.json().catch(() => null);
  if (!answer.ok) {
    throw Object.assign(new Error(described(answer.status, parsed, `${method} ${path}`)), { status: answer.status });
  }
  return parsed;
}

const sessionPath = (tail = "") => `/v1/recordings/${encodeURIComponent(state.session)}${tail}`;

// PUT one recording, reporting upload progress (0..1) to `progress`.
function putTake(index, blob, progress) {
  return new Promise((resolve, reject) => {
    const request = new XMLHttpRequest();
    request.open("PUT", sessionPath(`/takes/${index}`));
    for (const [name, value] of Object.entries(headers({ "content-type": blob.type || "application/octet-stream" }))) {
      request.setRequestHeader(name, value);
    }
    request.upload.onprogress = (event) => {
      if (event.lengthComputable) progress(event.loaded / event.total);
    };
    request.onload = () => {
      let parsed = null;
      try {
        parsed = JSON.parse(request.responseText);
      } catch (_) {
        // not JSON: the status says enough
      }
      if (request.status >= 200 && request.status < 300) resolve(parsed);
      else reject(Object.assign(new Error(described(request.status, parsed, "upload")), { status: request.status }));
    };
    request.onerror = () => reject(Object.assign(new Error("the connection failed during the upload"), { status: 0 }));
    request.send(blob);
  });
}

// ---- session ---------------------------------------------------------------------------

async function createSession(event) {
  event.preventDefault();
  clearErrors();
  const name = $("name").value.trim();
  if (!$("name").checkValidity()) {
    showError("the name takes 1 to 32 lower-case letters, digits or dashes");
    return;
  }
  const body = { name };
  const own = $("sentences").value.split("\n").map((line) => line.trim()).filter(Boolean);
  if (own.length) body.sentences = own;
  $("create").disabled = true;
  try {
    const created = await api("POST", "/v1/recordings", body);
    state.session = created.session;
    state.name = name;
    state.sentences = created.sentences;
    state.limits = created.limits;
  } catch (error) {
    $("create").disabled = false;
    showError(error.status === 409 ? `the name "${name}" is taken: choose another` : error.message);
    return;
  }
  for (const element of $("name-form").elements) element.disabled = true;
  const { max_recordings: count, max_bytes: bytes } = state.limits;
  $("session-info").textContent =
    `Session ${state.session}: ${state.sentences.length} sentences; ` +
    `at most ${count} recordings of ${megabytes(bytes)} each; ` +
    `training needs at least ${neededTakes()} good one${neededTakes() > 1 ? "s" : ""}.`;
  $("session-info").hidden = false;
  showSentence(0);
}

function megabytes(bytes) {
  if (bytes < 1e6) return `${Math.ceil(bytes / 1e3)} kB`;
  return `${(bytes / 1e6).toFixed(bytes < 1e7 ? 1 : 0)} MB`;
}

// How many good takes training needs (the server says; at least one).
function neededTakes() {
  return Math.max(1, state.limits?.min_recordings ?? 1);
}

function showSentence(position) {
  state.current = Math.max(0, Math.min(state.sentences.length - 1, position));
  const sentence = state.sentences[state.current];
  $("prompt").textContent = sentence.text;
  $("prompt-count").textContent = `Sentence ${state.current + 1} of ${state.sentences.length}`;
  render();
}

// ---- devices ---------------------------------------------------------------------------

function deviceMessage(error) {
  const reasons = {
    NotAllowedError: "permission to use the camera and microphone was denied: allow both for this site in the browser's settings, then try again",
    SecurityError: "permission to use the camera and microphone was denied: allow both for this site in the browser's settings, then try again",
    NotFoundError: "no camera or microphone was found: connect one and try again",
    OverconstrainedError: "no camera or microphone was found: connect one and try again",
    NotReadableError: "the camera or microphone is in use by another program: close it and try again",
    AbortError: "the camera or microphone is in use by another program: close it and try again",
  };
  return reasons[error.name] ?? `cannot open the camera and microphone (${error.name}: ${error.message})`;
}

async function openDevices() {
  if (state.stream !== null) return state.stream;
  if (!navigator.mediaDevices?.getUserMedia) {
    throw new Error("this page cannot reach a camera: browsers allow it only over https or on localhost");
  }
  let stream;
  try {
    stream = await navigator.mediaDevices.getUserMedia({
      video: { width: { ideal: 640 }, height: { ideal: 480 } },
      // The sound as spoken: no noise suppression or gain control between the voice and
      // the alignment.
      audio: { echoCancellation: false, noiseSuppression: false, autoGainControl: false },
    });
  } catch (error) {
    throw new Error(deviceMessage(error));
  }
  state.stream = stream;
  $("camera").srcObject = stream;
  $("camera").play().catch(() => {});
  startMeter(stream);
  return stream;
}

function closeDevices() {
  if (state.stream === null) return;
  for (const track of state.stream.getTracks()) track.stop();
  state.stream = null;
  $("camera").srcObject = null;
  if (state.meter !== null) state.meter.context.close();
  state.meter = null;
  $("level").value = 0;
}

function startMeter(stream) {
  const context = new AudioContext();
  const analyser = context.createAnalyser();
  analyser.fftSize = 1024;
  context.createMediaStreamSource(stream).connect(analyser);
  state.meter = { context, analyser, samples: new Float32Array(analyser.fftSize) };
}

function showLevel() {
  const meter = state.meter;
  if (meter !== null) {
    meter.analyser.getFloatTimeDomainData(meter.samples);
    let sum = 0;
    for (const value of meter.samples) sum += value * value;
    const level = Math.min(1, LEVEL_GAIN * Math.sqrt(sum / meter.samples.length));
    $("level").value = level;
    $("level").textContent = `${Math.round(100 * level)} %`;
    if (state.take !== null) log.peakLevel = Math.max(log.peakLevel, level);
  }
  requestAnimationFrame(showLevel);
}

async function toggleCheck() {
  clearErrors();
  if (state.stream !== null) {
    closeDevices();
  } else {
    try {
      await openDevices();
    } catch (error) {
      showError(error.message);
    }
  }
  render();
}

// ---- a take ----------------------------------------------------------------------------

async function startTake() {
  clearErrors();
  if (typeof MediaRecorder === "undefined") {
    showError("this browser cannot record video (it has no MediaRecorder): use a recent Chrome, Firefox or Safari");
    return;
  }
  const index = state.sentences[state.current].index;
  state.take = { index, chunks: [], bytes: 0, note: null };
  render();
  let stream;
  try {
    stream = await openDevices();
  } catch (error) {
    state.take = null;
    showError(error.message);
    render();
    return;
  }
  const mimeType = MIME_TYPES.find((type) => MediaRecorder.isTypeSupported(type));
  let recorder;
  try {
    recorder = new MediaRecorder(stream, mimeType ? { mimeType } : {});
  } catch (error) {
    closeDevices();
    state.take = null;
    showError(`this browser cannot record the camera and microphone (${error.name}: ${error.message})`);
    render();
    return;
  }
  const take = state.take;
  take.recorder = recorder;
  take.startedAt = performance.now();
  recorder.ondataavailable = (event) => {
    if (event.data.size === 0) return;
    take.chunks.push(event.data);
    take.bytes += event.data.size;
    if (take.bytes > SIZE_MARGIN * state.limits.max_bytes && recorder.state === "recording") {
      take.note = `stopped at the size limit of ${megabytes(state.limits.max_bytes)}`;
      recorder.stop();
    }
  };
  recorder.onerror = (event) => showError(`recording failed: ${event.error?.message ?? "the recorder stopped"}`);
  recorder.onstop = () => finishTake(take, recorder.mimeType);
  recorder.start(TIMESLICE_MS);
  log.recorded += 1;
  take.timer = setTimeout(() => {
    if (recorder.state === "recording") {
      take.note = `stopped after ${MAX_TAKE_S} s`;
      recorder.stop();
    }
  }, MAX_TAKE_S * 1000);
  showRecording();
  render();
}

function showRecording() {
  const take = state.take;
  if (take === null || take.recorder?.state !== "recording") return;
  const seconds = (performance.now() - take.startedAt) / 1000;
  $("recorder-status").textContent = `recording sentence ${state.current + 1}: ${seconds.toFixed(1)} s`;
  setTimeout(showRecording, 100);
}

function stopTake() {
  if (state.take?.recorder?.state === "recording") state.take.recorder.stop();
}

async function finishTake(take, mimeType) {
  clearTimeout(take.timer);
  closeDevices();
  state.take = null;
  const blob = new Blob(take.chunks, { type: mimeType || "video/webm" });
  const seconds = (performance.now() - take.startedAt) / 1000;
  $("recorder-status").textContent =
    `recorded ${seconds.toFixed(1)} s (${megabytes(blob.size)})` + (take.note ? `, ${take.note}` : "");
  if (blob.size === 0) {
    showError(`take ${take.index + 1} recorded nothing: try again`);
    render();
    return;
  }
  await upload(take.index, blob);
}

async function upload(index, blob) {
  const label = `take ${index + 1}`;
  state.uploading = true;
  state.uploadErrors.delete(index);
  $("upload").value = 0;
  $("upload-status").textContent = `uploading ${label} (${megabytes(blob.size)})`;
  render();
  try {
    const answer = await putTake(index, blob, (fraction) => {
      $("upload").value = fraction;
      $("upload-status").textContent = `uploading ${label}: ${Math.round(100 * fraction)} %`;
    });
    $("upload").value = 1;
    $("upload-status").textContent = `${label} uploaded (${megabytes(answer?.bytes ?? blob.size)})`;
    log.uploads.push({ index, bytes: blob.size, answer });
    state.takes.set(index, { index, bytes: answer?.bytes ?? blob.size, status: "uploaded", error: null });
    const next = state.sentences.findIndex((s, k) => k > state.current && !state.takes.has(s.index));
    if (next >= 0) showSentence(next);
  } catch (error) {
    const reason =
      error.status === 413
        ? `${label} is too big (${megabytes(blob.size)}; the server takes at most ` +
          `${megabytes(state.limits.max_bytes)}): record a shorter take`
        : error.status === 0
          ? `${label} was not uploaded: ${error.message}; check the connection and record it again`
          : `${label} was not uploaded: ${error.message}`;
    state.uploadErrors.set(index, reason);
    $("upload-status").textContent = `${label} not uploaded`;
    showError(reason);
  } finally {
    state.uploading = false;
    render();
  }
  await refresh().catch((error) => showError(error.message));
}

// ---- status and training --------------------------------------------------------------

async function refresh() {
  const status = await api("GET", sessionPath());
  log.polls += 1;
  const before = JSON.stringify([[...state.takes.values()], state.job]);
  state.takes = new Map(status.takes.map((take) => [take.index, take])); // what the server holds
  state.job = status.job ?? null;
  if (state.job !== null && !FINISHED.includes(state.job.state)) state.lastStep = state.job.state;
  render();
  return before !== JSON.stringify([[...state.takes.values()], state.job]);
}

async function train() {
  clearErrors();
  state.training = true;
  render();
  try {
    await api("POST", sessionPath("/train"));
  } catch (error) {
    state.training = false;
    showError(`training did not start: ${error.message}`);
    render();
    return;
  }
  follow();
}

// Poll the status until the job ends: FIRST_POLL_MS after a change, growing by POLL_GROWTH
// to MAX_POLL_MS while nothing changes (and while the server cannot be reached).
async function follow() {
  let delay = FIRST_POLL_MS;
  let unreachable = false;
  for (;;) {
    await new Promise((resolve) => setTimeout(resolve, delay));
    try {
      const changed = await refresh();
      unreachable = false;
      delay = changed ? FIRST_POLL_MS : Math.min(MAX_POLL_MS, delay * POLL_GROWTH);
    } catch (error) {
      if (!unreachable) showError(`${error.message}; still trying`);
      unreachable = true;
      delay = Math.min(MAX_POLL_MS, delay * POLL_GROWTH);
    }
    if (state.job !== null && FINISHED.includes(state.job.state)) break;
  }
  state.training = false;
  render();
  if (state.job.state === "failed") showError(`training failed: ${jobError(state.job)}`);
}

function jobError(job) {
  const error = job.error;
  if (!error) return "the server gave no reason";
  return typeof error === "string" ? error : `${error.code}: ${error.message}`;
}

// ---- drawing ---------------------------------------------------------------------------

function takeStatus(index) {
  if (state.take?.index === index) return ["recording", "recording"];
  const failedUpload = state.uploadErrors.get(index);
  if (failedUpload) return ["failed", `not uploaded: ${failedUpload}`];
  const take = state.takes.get(index);
  if (!take) return ["", "not recorded"];
  if (take.status === "failed") {
    const code = take.error?.code;
    const reason = REASONS[code] ?? code ?? "failed";
    return ["failed", `failed: ${reason}${take.error?.message ? ` (${take.error.message})` : ""}`];
  }
  if (take.status === "captured") return ["captured", "face and speech captured"];
  return ["uploaded", "uploaded"];
}

function renderTakes() {
  const rows = state.sentences.map((sentence, position) => {
    const [kind, text] = takeStatus(sentence.index);
    const take = state.takes.get(sentence.index);
    const row = document.createElement("tr");
    row.dataset.index = sentence.index;
    row.className = [kind, position === state.current ? "chosen" : ""].join(" ").trim();
    const number = document.createElement("td");
    const go = document.createElement("button");
    go.type = "button";
    go.textContent = String(position + 1);
    go.setAttribute("aria-label", `go to sentence ${position + 1}`);
    go.disabled = busy();
    go.addEventListener("click", () => showSentence(position));
    number.append(go);
    const cells = [sentence.text, take ? megabytes(take.bytes) : "–", text].map((value) => {
      const cell = document.createElement("td");
      cell.textContent = value;
      return cell;
    });
    cells[2].className = "status";
    row.append(number, ...cells);
    return row;
  });
  $("takes").tBodies[0].replaceChildren(...rows);
}

function renderJob() {
  const job = state.job;
  const failed = job?.state === "failed";
  const reached = job === null ? -1 : STEPS.indexOf(failed ? (state.lastStep ?? "queued") : job.state);
  for (const item of $("steps").children) {
    const step = STEPS.indexOf(item.dataset.step);
    item.className = "";
    item.removeAttribute("aria-current");
    if (job?.state === "done" || step < reached) item.className = "done";
    else if (step === reached) {
      item.className = failed ? "failed" : "current";
      item.setAttribute("aria-current", "step");
    }
  }
  $("job-progress").value = job === null ? 0 : job.state === "done" ? 1 : (job.progress ?? 0);
  const status = $("job-status");
  status.className = job?.state === "failed" ? "failed" : "";
  if (job === null) status.textContent = state.training ? "starting" : trainingHint();
  else if (job.state === "failed") status.textContent = `failed: ${jobError(job)}`;
  else if (job.state === "done") status.textContent = `done: the character "${job.character}" is served`;
  else {
    const label = $("steps").querySelector(`[data-step="${job.state}"]`)?.textContent ?? job.state;
    const detail = job.step && job.step !== job.state ? ` (${job.step})` : "";
    status.textContent = `${label}${detail}: ${Math.round(100 * (job.progress ?? 0))} %`;
  }
  const done = job?.state === "done";
  $("speak").hidden = !done;
  if (done) $("speak-link").href = withToken(`/?character=${encodeURIComponent(job.character)}`);
}

function goodTakes() {
  return [...state.takes.values()].filter((take) => take.status !== "failed").length;
}

function trainingHint() {
  if (state.session === null) return "not started";
  const missing = neededTakes() - goodTakes();
  return missing > 0 ? `record ${missing} more sentence${missing > 1 ? "s" : ""} to train` : "ready to train";
}

function busy() {
  return state.take !== null || state.uploading || state.training;
}

function render() {
  const started = state.session !== null;
  const recording = state.take !== null;
  const jobRunning = state.training || (state.job !== null && !FINISHED.includes(state.job.state));
  const done = state.job?.state === "done";
  $("previous").disabled = !started || busy() || state.current === 0;
  $("next").disabled = !started || busy() || state.current >= state.sentences.length - 1;
  $("check").disabled = recording || jobRunning || done;
  $("check").textContent = state.stream !== null && !recording ? "Turn the camera off" : "Check camera";
  const taken = started && state.takes.has(state.sentences[state.current].index);
  $("record-take").disabled = !started || busy() || jobRunning || done;
  $("record-take").textContent = taken ? "Record again" : "Record";
  $("stop").disabled = !recording || state.take.recorder === undefined;
  const status = $("recorder-status");
  status.classList.toggle("recording", recording);
  if (recording && state.take.recorder === undefined) status.textContent = "opening the camera and microphone";
  $("train").disabled = !started || goodTakes() < neededTakes() || busy() || jobRunning || done;
  if (started) renderTakes();
  renderJob();
}

// ---- start -----------------------------------------------------------------------------

keepToken();
$("name-form").addEventListener("submit", createSession);
$("previous").addEventListener("click", () => showSentence(state.current - 1));
$("next").addEventListener("click", () => showSentence(state.current + 1));
$("check").addEventListener("click", toggleCheck);
$("record-take").addEventListener("click", startTake);
$("stop").addEventListener("click", stopTake);
$("train").addEventListener("click", train);
if (typeof MediaRecorder === "undefined") {
  showError("this browser cannot record video (it has no MediaRecorder): use a recent Chrome, Firefox or Safari");
}
render();
requestAnimationFrame(showLevel);
document.body.dataset.ready = "true";
