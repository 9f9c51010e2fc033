// A 2D face in SVG driven by ARKit blendshape weights (0..1).
// Drawn back to front: shoulders, neck, the back of the hair, ears, head, fringe, cheeks,
// eyes, brows, nose, then the mouth. The mouth's inside (upper teeth fixed to the skull,
// lower teeth and tongue riding on the jaw) is clipped to the opening between the lips,
// so it shows only where the lips part.
// Every channel of the demo character moves something: the jaw drops the chin, the lower
// teeth, the tongue and the lower lip; lip closure, funnel, pucker, stretch, smile, press,
// roll, shrug, upper-up and lower-down shape the lips and the mouth opening; cheekPuff
// swells the cheeks; the brows rise and fall at their inner and outer ends; blinks close
// the upper lids and squints raise the lower ones. "Left" is the face's own left, drawn
// on the viewer's right.

const SVG_NS = "http://www.w3.org/2000/svg";
const CX = 100;
const EYE_Y = 100;
const MOUTH_Y = 168;
const CHIN_Y = 212;
const CHIN_DROP = 30; // SVG units the chin and lower teeth fall at jawOpen 1
const LIP_GAP = 62; // SVG units the lips part at jawOpen 1 (the lower lip travels further)
let faces = 0; // numbers each face's clip path, so two faces on a page keep their own

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

// A row of teeth: a rounded band from x0 to x1 whose free edge (y `edge`) is scalloped,
// rooted at y `root` (above the edge for upper teeth, below it for lower ones).
function teethRow(x0, x1, root, edge, count) {
  const width = (x1 - x0) / count;
  const bulge = Math.sign(edge - root) * 1.2;
  let d = `M${fmt(x0)},${fmt(root)} L${fmt(x0)},${fmt(edge)}`;
  for (let k = 0; k < count; k++) {
    const a = x0 + k * width;
    d += ` Q${fmt(a + width / 2)},${fmt(edge + bulge)} ${fmt(a + width)},${fmt(edge)}`;
  }
  return d + ` L${fmt(x1)},${fmt(root)} Z`;
}

export class Face {
  constructor(svg) {
    this.svg = svg;
    svg.setAttribute("viewBox", "0 0 200 240");
    svg.classList.add("face");
    const clipId = `face-mouth-clip-${++faces}`;
    const clip = element(element(svg, "defs", {}), "clipPath", { id: clipId });
    this.clipShape = element(clip, "path", {});
    this.drawStill(svg);
    this.head = element(svg, "path", { id: "head", class: "skin" });
    this.fringe = element(svg, "path", {
      id: "fringe",
      class: "hair fringe",
      d:
        "M26,96 C22,52 48,24 100,22 C152,24 178,52 174,96 C164,72 150,58 132,52 " +
        "C118,66 92,68 72,60 C64,70 50,76 38,76 C32,82 28,88 26,96 Z",
    });
    this.cheeks = { Left: null, Right: null };
    this.eyes = {};
    this.brows = {};
    for (const side of ["Right", "Left"]) {
      const sign = side === "Left" ? 1 : -1;
      const x = CX + sign * 32;
      this.cheeks[side] = element(svg, "ellipse", { id: `cheek${side}`, class: "cheek" });
      element(svg, "ellipse", { cx: x, cy: EYE_Y, rx: 15, ry: 9, class: "eye-white" });
      element(svg, "circle", { cx: x, cy: EYE_Y, r: 7.5, class: "iris" });
      const pupil = element(svg, "circle", { cx: x, cy: EYE_Y, r: 3.8, class: "pupil" });
      element(svg, "circle", { cx: x + 2.5, cy: EYE_Y - 2.5, r: 1.6, class: "glint" });
      const lid = element(svg, "path", { id: `lid${side}`, class: "lid" });
      const lower = element(svg, "path", { id: `lowerLid${side}`, class: "lid" });
      this.eyes[side] = { x, pupil, lid, lower };
      this.brows[side] = element(svg, "path", { id: `brow${side}`, class: "brow" });
    }
    element(svg, "path", {
      id: "nose",
      d: "M96,112 Q93,130 90,138 Q94,144 100,143 Q106,144 110,138 Q107,130 104,118",
      class: "nose",
    });
    element(svg, "path", { d: "M93,139 q2,1.5 4,0.5 M103,139.5 q2,1 4,-0.5", class: "nostril" });
    this.opening = element(svg, "path", { id: "mouth-opening", class: "mouth-inside" });
    const inside = element(svg, "g", { id: "mouth-inner", "clip-path": `url(#${clipId})` });
    this.tongue = element(inside, "path", { id: "tongue", class: "tongue" });
    this.teeth = element(inside, "path", { id: "teeth", class: "teeth" });
    this.lowerTeeth = element(inside, "path", { id: "lower-teeth", class: "teeth" });
    this.upperLip = element(svg, "path", { id: "upper-lip", class: "lip" });
    this.lowerLip = element(svg, "path", { id: "lower-lip", class: "lip" });
    this.values = {};
    this.apply({});
  }

  // The parts no channel moves, behind the head: shoulders, neck, the hair's back, ears.
  drawStill(svg) {
    element(svg, "path", {
      id: "shoulders",
      class: "shirt",
      d: "M4,240 C8,230 34,222 70,220 L130,220 C166,222 192,230 196,240 Z",
    });
    element(svg, "path", {
      id: "neck",
      class: "skin",
      d: "M74,170 L74,224 Q100,236 126,224 L126,170 Z",
    });
    element(svg, "path", {
      id: "hair",
      class: "hair",
      d:
        "M100,14 C40,14 10,56 12,112 C13,140 16,160 24,178 L34,178 C26,150 24,120 28,96 " +
        "L172,96 C176,120 174,150 166,178 L176,178 C184,160 187,140 188,112 " +
        "C190,56 160,14 100,14 Z",
    });
    for (const side of ["Right", "Left"]) {
      const sign = side === "Left" ? 1 : -1;
      const id = `ear-${side.toLowerCase()}`;
      const base = CX + sign * 74;
      const tip = CX + sign * 88;
      element(svg, "path", {
        id,
        class: "skin",
        d:
          `M${base},102 C${tip},92 ${tip + sign * 2},112 ${tip - sign * 1},124 ` +
          `C${tip - sign * 3},134 ${base + sign * 4},140 ${base},138 Z`,
      });
      element(svg, "path", {
        class: "ear-fold",
        d: `M${base + sign * 3},108 C${tip - sign * 3},102 ${tip - sign * 2},120 ${base + sign * 5},130`,
      });
    }
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
    const drop = CHIN_DROP * jaw;
    // The jaw carries the chin: the head's outline below the cheeks moves down with it.
    this.head.setAttribute(
      "d",
      `M22,118 C22,8 178,8 178,118 C178,${fmt(178 + drop / 2)} ${fmt(140)},${fmt(CHIN_Y - 2 + drop)} ` +
        `${CX},${fmt(CHIN_Y + drop)} C60,${fmt(CHIN_Y - 2 + drop)} 22,${fmt(178 + drop / 2)} 22,118 Z`
    );
    const round = v("mouthFunnel");
    const pucker = v("mouthPucker");
    const press = (v("mouthPressLeft") + v("mouthPressRight")) / 2;
    // ARKit's mouthClose closes the lips against an open jaw: they meet when it equals jawOpen.
    const close = v("mouthClose");
    // Pressed lips squeeze the opening shut from the corners in.
    const gapCenter = Math.max(
      0,
      (LIP_GAP * Math.max(0, jaw - close) + 8 * round - 3 * v("mouthShrugLower")) *
        (1 - 0.5 * press)
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
          0.15 * v(`mouthPress${name}`));
      const cornerY =
        MOUTH_Y +
        0.3 * drop -
        8 * v(`mouthSmile${name}`) +
        6 * v(`mouthFrown${name}`) +
        3 * v(`mouthStretch${name}`);
      side[name] = {
        x: CX + sign * half,
        cornerY,
        upper: MOUTH_Y - 7 * v(`mouthUpperUp${name}`) - 2 * v("mouthShrugUpper"),
        lower:
          MOUTH_Y + gapCenter * 0.8 + 8 * v(`mouthLowerDown${name}`) - 2 * v("mouthShrugLower"),
        sign,
        half,
      };
    }
    const upperMid = MOUTH_Y - gapCenter * 0.15 - 2 * v("mouthShrugUpper");
    // Beyond meeting the upper lip, mouthClose presses the lower lip up against it.
    const lowerMid = MOUTH_Y + gapCenter * 0.85 - 3 * v("mouthShrugLower") - 2 * close;
    // Pucker and funnel push the lips out (fuller); rolling tucks them in (thinner).
    const full = (1 + 0.7 * pucker + 0.3 * round) * (1 - 0.35 * press);
    const thickUpper = 6.5 * (1 - 0.75 * v("mouthRollUpper")) * full;
    const thickLower =
      8 * (1 - 0.75 * v("mouthRollLower")) * full * (1 + 0.3 * v("mouthShrugLower")) *
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
    const opening = smoothClosed([corners[0], ...innerUpper, corners[1], ...innerLower]);
    this.opening.setAttribute("d", opening);
    this.clipShape.setAttribute("d", opening);
    this.drawInside(drop, upperMid);
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

  // The upper teeth hang from the skull just behind the upper lip (lifting a little with it);
  // the lower teeth and the tongue ride on the jaw, `drop` below their rest.
  drawInside(drop, upperMid) {
    const upperEdge = Math.min(MOUTH_Y + 3, upperMid + 6);
    this.teeth.setAttribute("d", teethRow(CX - 17, CX + 17, upperEdge - 12, upperEdge, 6));
    const lowerEdge = MOUTH_Y + 4 + drop;
    this.lowerTeeth.setAttribute("d", teethRow(CX - 14, CX + 14, lowerEdge + 6, lowerEdge, 6));
    const top = lowerEdge - 8;
    this.tongue.setAttribute(
      "d",
      `M${CX - 22},${fmt(top + 40)} C${CX - 22},${fmt(top - 1)} ${CX - 6},${fmt(top)} ${CX},${fmt(top + 2)} ` +
        `C${CX + 6},${fmt(top)} ${CX + 22},${fmt(top - 1)} ${CX + 22},${fmt(top + 40)} Z`
    );
  }

  drawEyes(v) {
    // Quadratic lids: a control point at y puts the curve's middle at (200 + 2y) / 4.
    for (const [side, eye] of Object.entries(this.eyes)) {
      const upperEdge = 80 + 40 * v(`eyeBlink${side}`);
      eye.lid.setAttribute(
        "d",
        `M${eye.x - 16},${EYE_Y} Q${eye.x},78 ${eye.x + 16},${EYE_Y} ` +
          `Q${eye.x},${fmt(upperEdge)} ${eye.x - 16},${EYE_Y} Z`
      );
      const lowerEdge = 120 - 22 * v(`eyeSquint${side}`);
      eye.lower.setAttribute(
        "d",
        `M${eye.x - 16},${EYE_Y} Q${eye.x},121 ${eye.x + 16},${EYE_Y} ` +
          `Q${eye.x},${fmt(lowerEdge)} ${eye.x - 16},${EYE_Y} Z`
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
