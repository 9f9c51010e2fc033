// Phone files read in the browser: HTK/MOCHA .lab and Praat TextGrid (long or short text
// format). Both give [{phoneme, start, end}] in seconds, empty labels as "sil"; the server
// detects the notation (phoneme_source "auto").

export function parseLab(text) {
  const rows = [];
  for (const [number, line] of text.split(/\r?\n/).entries()) {
    const fields = line.trim().split(/\s+/);
    if (fields.length < 3 || fields[0] === "") continue;
    const start = Number(fields[0]);
    const end = Number(fields[1]);
    if (!Number.isFinite(start) || !Number.isFinite(end)) {
      throw new Error(`.lab line ${number + 1}: expected "start end label"`);
    }
    rows.push([start, end, fields[2]]);
  }
  if (!rows.length) throw new Error(".lab file holds no intervals");
  // HTK writes 100 ns units: integers, and far beyond an utterance's seconds.
  const integral = rows.every(([s, e]) => Number.isInteger(s) && Number.isInteger(e));
  const scale = integral && rows[rows.length - 1][1] > 10000 ? 1e-7 : 1;
  return spans(rows.map(([s, e, label]) => [s * scale, e * scale, label]));
}

export function parseTextGrid(text) {
  // The long format numbers its items and intervals ("item [1]:"); those are not values.
  const values = text.replace(/\[\d*\]/g, "");
  const tokens = [...values.matchAll(/"((?:[^"]|"")*)"|([-+]?\d*\.?\d+(?:[eE][-+]?\d+)?)/g)].map(
    (m) => (m[1] !== undefined ? { text: m[1].replace(/""/g, '"') } : { number: Number(m[2]) })
  );
  // Tokens: "ooTextFile" "TextGrid" xmin xmax <exists> size, then per tier:
  // class name xmin xmax n, then n × (xmin xmax text).
  let i = tokens.findIndex((t) => t.text === "IntervalTier" || t.text === "TextTier");
  const tiers = [];
  while (i >= 0 && i < tokens.length) {
    const kind = tokens[i].text;
    const name = tokens[i + 1].text;
    const count = tokens[i + 4].number;
    i += 5;
    const rows = [];
    for (let k = 0; k < count; k++) {
      if (kind === "IntervalTier") {
        rows.push([tokens[i].number, tokens[i + 1].number, tokens[i + 2].text]);
        i += 3;
      } else {
        i += 2;
      }
    }
    if (kind === "IntervalTier") tiers.push({ name, rows });
    while (i < tokens.length && tokens[i].text !== "IntervalTier" && tokens[i].text !== "TextTier") i++;
  }
  if (!tiers.length) throw new Error("the TextGrid has no interval tier");
  const phoneTier =
    tiers.find((t) => /^(phones?|phonemes?|segments?|MAU)$/i.test(t.name)) ?? tiers[tiers.length - 1];
  return spans(phoneTier.rows);
}

function spans(rows) {
  const items = [];
  for (const [start, end, label] of rows) {
    if (!(end > start)) continue;
    items.push({ phoneme: label.trim() || "sil", start, end });
  }
  if (!items.length) throw new Error("the file holds no phoneme with a duration");
  return items;
}
