// What the demo page and the VRM page share: the lipstream protocol on one WebSocket (JSON
// subprotocol), the clock that sound and face share, speech scheduled on it, the server's
// engines and characters as controls, and the errors shown to the user.
//
// The clock is the AudioContext's while it runs, else the page's monotonic clock (no sound
// device). A page fixes a request's t0 on it at the first `audio` or `frames` message; each
// speech chunk plays at t0 + its `start`, and each animation frame shows the frame for
// now() - t0, not the last frame that arrived.

export const SUBPROTOCOL = "lipstream.v1.json";

const $ = (id) => document.getElementById(id);
let audioContext = null;
let socket = null;

// ---- clock ---------------------------------------------------------------------------

export function ensureAudio() {
  if (audioContext === null) audioContext = new AudioContext();
  if (audioContext.state === "suspended") audioContext.resume();
  return audioContext;
}

export function audioRunning() {
  return audioContext !== null && audioContext.state === "running";
}

export function now() {
  return audioRunning() ? audioContext.currentTime : performance.now() / 1000;
}

export function clockName() {
  return audioRunning() ? `audio (${audioContext.sampleRate} Hz)` : "page (audio not running)";
}

// Play `buffer` from time `at` on the audio clock; if `at` has passed, at once, from where it
// would be by now. The source, to stop it.
export function playAt(buffer, at) {
  const source = audioContext.createBufferSource();
  source.buffer = buffer;
  source.connect(audioContext.destination);
  source.start(Math.max(at, now()), Math.max(0, now() - at));
  return source;
}

// Schedule an `audio` message's speech at t0 + its start: the source, or null without sound.
export function playSpeech(message, t0) {
  if (!audioRunning()) return null;
  const samples = pcm16ToFloat(message.pcm16);
  const buffer = audioContext.createBuffer(1, samples.length, message.sample_rate);
  buffer.copyToChannel(samples, 0);
  return playAt(buffer, t0 + (message.start ?? 0));
}

export function pcm16ToFloat(base64) {
  const bytes = Uint8Array.from(atob(base64), (c) => c.charCodeAt(0));
  const view = new DataView(bytes.buffer);
  const samples = new Float32Array(bytes.length >> 1);
  for (let i = 0; i < samples.length; i++) samples[i] = view.getInt16(2 * i, true) / 32768;
  return samples;
}

// ---- protocol ------------------------------------------------------------------------

// The page's access token (`?access_token=`), if any, goes to the WebSocket too.
function socketUrl() {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  const token = new URLSearchParams(location.search).get("access_token");
  const query = token === null ? "" : `?access_token=${encodeURIComponent(token)}`;
  return `${scheme}//${location.host}/v1/stream${query}`;
}

// Open the WebSocket, or reuse the open one; `receive` gets every decoded message.
export function connect(receive) {
  if (socket !== null && socket.readyState <= WebSocket.OPEN) return socket.opened;
  const ws = new WebSocket(socketUrl(), [SUBPROTOCOL]);
  socket = ws;
  ws.opened = new Promise((resolve, reject) => {
    ws.onopen = () => resolve(ws);
    ws.onerror = () => reject(new Error("cannot open the WebSocket /v1/stream"));
  });
  ws.onmessage = (event) => receive(JSON.parse(event.data));
  ws.onclose = (event) => {
    if (socket === ws) socket = null;
    if (event.code !== 1000 && event.code !== 1001) {
      showError(`connection closed (${event.code}${event.reason ? ": " + event.reason : ""})`);
    }
  };
  return ws.opened;
}

export function connected() {
  return socket !== null;
}

export function send(message) {
  socket.send(JSON.stringify({ v: 1, ...message }));
}

// ---- errors --------------------------------------------------------------------------

export const errors = []; // every error shown, for tests and the console

export function showError(text) {
  errors.push(text);
  const line = document.createElement("div");
  line.className = "error";
  line.textContent = text;
  $("errors").appendChild(line);
}

export function clearErrors() {
  $("errors").replaceChildren();
}

// ---- controls ------------------------------------------------------------------------

export async function getJson(path) {
  const answer = await fetch(path);
  if (!answer.ok) throw new Error(`${path}: HTTP ${answer.status}`);
  return answer.json();
}

// Fill the #engine and #character selects from the server, then the page's own controls
// (`more`), then mark the body ready. `?character=<name>` chooses that character, and an
// engine it has (the default engine when it has it); the characters are listed again when
// the page is shown again, so one trained meanwhile appears.
export async function loadControls(defaultEngine, more = async () => {}) {
  keepToken();
  let engines;
  let characters;
  try {
    [engines, characters] = await Promise.all([getJson("/v1/engines"), getJson("/v1/characters")]);
  } catch (error) {
    showError(`cannot list the engines: ${error.message}`);
    return;
  }
  const select = $("engine");
  for (const engine of engines.engines) {
    const option = new Option(engine.loaded ? engine.name : `${engine.name} (not loaded)`, engine.name);
    option.disabled = !engine.loaded;
    select.add(option);
  }
  const loaded = engines.engines.filter((e) => e.loaded).map((e) => e.name);
  const wanted = new URLSearchParams(location.search).get("character");
  const found = characters.characters.find((c) => c.name === wanted);
  const usable = (found?.engines ?? []).filter((name) => loaded.includes(name));
  const offered = usable.length ? usable : loaded;
  select.value = offered.includes(defaultEngine) ? defaultEngine : (offered[0] ?? "");
  if (wanted !== null && !usable.length) showError(`the server has no character "${wanted}" to speak with`);
  const fillCharacters = () => {
    const chosen = $("character");
    const previous = chosen.value || (usable.length ? wanted : "");
    chosen.replaceChildren();
    for (const character of characters.characters) {
      if (character.engines.includes(select.value)) chosen.add(new Option(character.name));
    }
    if ([...chosen.options].some((o) => o.value === previous)) chosen.value = previous;
  };
  select.addEventListener("change", fillCharacters);
  document.addEventListener("visibilitychange", async () => {
    if (document.visibilityState !== "visible") return;
    try {
      characters = await getJson("/v1/characters");
      fillCharacters();
    } catch (_) {
      // the next request shows what is wrong
    }
  });
  fillCharacters();
  await more();
  document.body.dataset.ready = "true";
}

// Links marked `keeps-token` carry the page's `?access_token=` to the page they open.
export function keepToken() {
  const token = new URLSearchParams(location.search).get("access_token");
  if (token === null) return;
  for (const link of document.querySelectorAll("a.keeps-token")) {
    const target = new URL(link.getAttribute("href"), location.href);
    target.searchParams.set("access_token", token);
    link.href = target.pathname + target.search;
  }
}
