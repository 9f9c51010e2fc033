// A 2D face in SVG driven by ARKit blendshape weights (0..1).
// Every channel of the demo character moves something: the jaw drops the chin and
// the lower lip; lip closure, funnel, pucker, stretch, smile, press, roll, shrug,
// upper-up and lower-down shape the lips and the mouth opening; cheekPuff swells
// the cheeks; the brows rise and fall at their inner and outer ends; blinks close
// the upper lids and squints raise the lower ones. "Left" is the face's own left,
// drawn on the viewer's right.

const SVG_NS = "http://www.w3.org/2000/svg";
const CX = 100;
const MOUTH_Y = 168;

function element(parent, name, attributes) {
  const node = document.createElementNS(SVG_NS, name);
  for (const [key, value] of Object.entries(attributes)) node.setAttribute(key, value);
  parent.appendChild(node);
  return node;
}

function fmt(value) {
  return (Math.round(value * 100) / 100).toString();
}

// A closed smooth path through points (quadratic curves through the midpoints).
function smoothClosed(points) {
  const n = points.length;
  const mid = (a, b) => [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2];
  let d = `M${fmt(mid(points[n - 1], points[0])[0])},${fmt(mid(points[n - 1], points[0])[1])}`;
  for (let i = 0; i < n; i++) {
    const p = points[i];
    const m = mid(p, points[(i + 1) % n]);
    d += ` Q${fmt(p[0])},${fmt(p[1])} ${fmt(m[0])},${fmt(m[1])}`;
  }
  return d + " Z";
}

export class Face {
  constructor(svg) {
    this.svg = svg;
    svg.setAttribute("viewBox", "0 0 200 240");
    this.head = element(svg, "path", { id: "head", class: "skin" });
    this.cheeks = { Left: null, Right: null };
    this.eyes = {};
    this.brows = {};
    for (const side of ["Right", "Left"]) {
      const sign = side === "Left" ? 1 : -1;
      const x = CX + sign * 32;
      this.cheeks[side] = element(svg, "ellipse", { id: `cheek${side}`, class: "cheek" });
      element(svg, "ellipse", { cx: x, cy: 100, rx: 15, ry: 9, class: "eye-white" });
      const pupil = element(svg, "circle", { cx: x, cy: 100, r: 5, class: "pupil" });
      const lid = element(svg, "path", { id: `lid${side}`, class: "lid" });
      const lower = element(svg, "path", { id: `lowerLid${side}`, class: "lid" });
      this.eyes[side] = { x, pupil, lid, lower };
      this.brows[side] = element(svg, "path", { id: `brow${side}`, class: "brow" });
    }
    element(svg, "path", { d: "M100,112 Q94,138 100,142 Q106,138 100,112", class: "nose" });
    this.opening = element(svg, "path", { id: "mouth-opening", class: "mouth-inside" });
    this.teeth = element(svg, "rect", { id: "teeth", class: "teeth" });
    this.upperLip = element(svg, "path", { id: "upper-lip", class: "lip" });
    this.lowerLip = element(svg, "path", { id: "lower-lip", class: "lip" });
    this.values = {};
    this.apply({});
  }

  // Draw the face for a map channel name -> weight; missing channels count as 0.
  apply(values) {
    this.values = { ...values };
    const v = (name) => Math.max(0, Math.min(1, Number(values[name] ?? 0)));
    this.drawMouth(v);
    this.drawEyes(v);
    this.drawBrows(v);
    this.drawCheeks(v);
  }

  drawMouth(v) {
    const jaw = v("jawOpen");
    const drop = 30 * jaw;
    // The jaw carries the chin: the head's outline below the cheeks moves down with it.
    this.head.setAttribute(
      "d",
      `M22,118 C22,8 178,8 178,118 C178,${fmt(178 + drop / 2)} ${fmt(140)},${fmt(210 + drop)} ` +
        `${CX},${fmt(212 + drop)} C60,${fmt(210 + drop)} 22,${fmt(178 + drop / 2)} 22,118 Z`
    );
    const round = v("mouthFunnel");
    const pucker = v("mouthPucker");
    // ARKit's mouthClose closes the lips against an open jaw: they meet when it equals jawOpen.
    const close = v("mouthClose");
    const gapCenter = Math.max(
      0,
      90 * Math.max(0, jaw - close) + 8 * round - 3 * v("mouthShrugLower")
    );
    const side = {};
    for (const name of ["Left", "Right"]) {
      const sign = name === "Left" ? 1 : -1;
      const half =
        24 *
        (1 +
          0.35 * v(`mouthStretch${name}`) +
          0.25 * v(`mouthSmile${name}`) -
          0.45 * pucker -
          0.3 * round -
          0.1 * v(`mouthPress${name}`));
      const cornerY =
        MOUTH_Y + 0.3 * drop - 8 * v(`mouthSmile${name}`) + 3 * v(`mouthStretch${name}`);
      side[name] = {
        x: CX + sign * half,
        cornerY,
        upper: MOUTH_Y - 7 * v(`mouthUpperUp${name}`) - 2 * v("mouthShrugUpper"),
        lower:
          MOUTH_Y + gapCenter * 0.8 + 8 * v(`mouthLowerDown${name}`) - 2 * v("mouthShrugLower"),
        press: v(`mouthPress${name}`),
        sign,
        half,
      };
    }
    const upperMid = MOUTH_Y - gapCenter * 0.15 - 2 * v("mouthShrugUpper");
    // Beyond meeting the upper lip, mouthClose presses the lower lip up against it.
    const lowerMid = MOUTH_Y + gapCenter * 0.85 - 3 * v("mouthShrugLower") - 2 * close;
    const thickUpper =
      6.5 * (1 - 0.75 * v("mouthRollUpper")) * (1 + 0.7 * pucker + 0.3 * round) *
      (1 - 0.35 * (side.Left.press + side.Right.press) / 2);
    const thickLower =
      8 * (1 - 0.75 * v("mouthRollLower")) * (1 + 0.7 * pucker + 0.3 * round) *
      (1 - 0.35 * (side.Left.press + side.Right.press) / 2) * (1 + 0.3 * v("mouthShrugLower")) *
      (1 - 0.2 * close);
    const L = side.Left;
    const R = side.Right;
    const at = (s, f) => CX + s.sign * s.half * f;
    const innerUpper = [
      [at(R, 0.55), (R.upper + upperMid) / 2],
      [CX, upperMid],
      [at(L, 0.55), (L.upper + upperMid) / 2],
    ];
    const innerLower = [
      [at(L, 0.55), (L.lower + lowerMid) / 2],
      [CX, lowerMid],
      [at(R, 0.55), (R.lower + lowerMid) / 2],
    ];
    const corners = [
      [R.x, R.cornerY],
      [L.x, L.cornerY],
    ];
    this.opening.setAttribute(
      "d",
      smoothClosed([corners[0], ...innerUpper, corners[1], ...innerLower])
    );
    const teethTop = upperMid + 1;
    this.teeth.setAttribute("x", fmt(CX - 14));
    this.teeth.setAttribute("y", fmt(teethTop));
    this.teeth.setAttribute("width", "28");
    this.teeth.setAttribute("height", fmt(Math.max(0, Math.min(5, lowerMid - teethTop - 1))));
    const outerUpper = innerUpper
      .slice()
      .reverse()
      .map(([x, y], i) => [x, y - thickUpper * (i === 1 ? 1 : 0.8)]);
    const outerLower = innerLower
      .slice()
      .reverse()
      .map(([x, y], i) => [x, y + thickLower * (i === 1 ? 1 : 0.8)]);
    this.upperLip.setAttribute(
      "d",
      smoothClosed([corners[0], ...innerUpper, corners[1], ...outerUpper])
    );
    this.lowerLip.setAttribute(
      "d",
      smoothClosed([corners[1], ...innerLower, corners[0], ...outerLower])
    );
  }

  drawEyes(v) {
    // Quadratic lids: a control point at y puts the curve's middle at (200 + 2y) / 4.
    for (const [side, eye] of Object.entries(this.eyes)) {
      const upperEdge = 80 + 40 * v(`eyeBlink${side}`);
      eye.lid.setAttribute(
        "d",
        `M${eye.x - 16},100 Q${eye.x},78 ${eye.x + 16},100 ` +
          `Q${eye.x},${fmt(upperEdge)} ${eye.x - 16},100 Z`
      );
      const lowerEdge = 120 - 22 * v(`eyeSquint${side}`);
      eye.lower.setAttribute(
        "d",
        `M${eye.x - 16},100 Q${eye.x},121 ${eye.x + 16},100 ` +
          `Q${eye.x},${fmt(lowerEdge)} ${eye.x - 16},100 Z`
      );
    }
  }

  drawBrows(v) {
    for (const [side, brow] of Object.entries(this.brows)) {
      const sign = side === "Left" ? 1 : -1;
      const down = v(`browDown${side}`);
      const inner = 78 - 9 * v("browInnerUp") + 6 * down;
      const outer = 80 - 9 * v(`browOuterUp${side}`) + 2 * down;
      const innerX = CX + sign * 14;
      const outerX = CX + sign * 50;
      brow.setAttribute(
        "d",
        `M${innerX},${fmt(inner)} Q${(innerX + outerX) / 2},${fmt(Math.min(inner, outer) - 6)} ` +
          `${outerX},${fmt(outer)}`
      );
    }
  }

  drawCheeks(v) {
    const puff = v("cheekPuff");
    for (const [side, cheek] of Object.entries(this.cheeks)) {
      const sign = side === "Left" ? 1 : -1;
      cheek.setAttribute("cx", fmt(CX + sign * (48 + 8 * puff)));
      cheek.setAttribute("cy", "150");
      cheek.setAttribute("rx", fmt(12 + 9 * puff));
      cheek.setAttribute("ry", fmt(9 + 6 * puff));
      cheek.setAttribute("opacity", fmt(0.25 + 0.5 * puff));
    }
  }

  // What the page drew, for readouts and tests: the mouth opening's height and width.
  mouthOpening() {
    const box = this.opening.getBBox();
    return { width: box.width, height: box.height };
  }
}
