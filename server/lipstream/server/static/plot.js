// A live plot of chosen channels over the utterance clock, on a canvas.
// Redrawn whenever frames arrive; a vertical cursor marks the playback time.

const COLOURS = ["#d9480f", "#1971c2", "#2f9e44", "#9c36b5", "#e8590c", "#0c8599"];

export class Plot {
  constructor(canvas) {
    this.canvas = canvas;
    this.context = canvas.getContext("2d");
  }

  // frames: array (index = frame) of rows or undefined; channels: names of the columns.
  draw(frames, fps, channels, chosen, cursorS) {
    const { canvas, context } = this;
    const width = canvas.width;
    const height = canvas.height;
    context.clearRect(0, 0, width, height);
    context.fillStyle = "#fbfaf7";
    context.fillRect(0, 0, width, height);
    const durationS = Math.max(1, frames.length / fps);
    const x = (t) => 40 + ((width - 50) * t) / durationS;
    const y = (value) => height - 20 - (height - 30) * value;
    context.strokeStyle = "#ccc";
    context.lineWidth = 1;
    context.beginPath();
    for (const value of [0, 0.5, 1]) {
      context.moveTo(40, y(value));
      context.lineTo(width - 10, y(value));
    }
    context.stroke();
    context.fillStyle = "#555";
    context.font = "11px sans-serif";
    context.fillText("1", 26, y(1) + 4);
    context.fillText("0", 26, y(0) + 4);
    context.fillText(`${durationS.toFixed(1)} s`, width - 40, height - 5);
    chosen.forEach((name, k) => {
      const column = channels.indexOf(name);
      if (column < 0) return;
      context.strokeStyle = COLOURS[k % COLOURS.length];
      context.lineWidth = 1.6;
      context.beginPath();
      let drawing = false;
      frames.forEach((row, index) => {
        if (!row) {
          drawing = false;
          return;
        }
        const px = x(index / fps);
        const py = y(row[column]);
        if (drawing) context.lineTo(px, py);
        else context.moveTo(px, py);
        drawing = true;
      });
      context.stroke();
      context.fillStyle = COLOURS[k % COLOURS.length];
      context.fillText(name, 46 + 110 * k, 12);
    });
    if (cursorS !== null && cursorS >= 0) {
      context.strokeStyle = "#222";
      context.beginPath();
      context.moveTo(x(cursorS), 16);
      context.lineTo(x(cursorS), height - 20);
      context.stroke();
    }
  }
}
