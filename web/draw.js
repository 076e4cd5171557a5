// Canvas drawings of a session: the trajectory top-down (x right, z forward:
// the world frame is the first camera's, y down) with its planes, a side view
// (height along the drive) and small time series. Each view fits its data.

export const QUALITY_COLOURS = {
  ANCHOR: '#1764ab',
  FRAME: '#2e8540',
  INTERPOLATED: '#c25e00',
  COASTING: '#c0162b',
  MOTION_ONLY: '#7d5ba6',
  KIND_UNSPECIFIED: '#6b6b6b',
};
const PLANE_COLOUR = '#7a4fa0';
const INK = '#1b1b1b';
const MARGIN_PX = 28;

// Sizes the canvas' bitmap to its CSS box (sharp on high-DPI screens) and
// returns a context in CSS pixels.
function context(canvas) {
  const dpr = window.devicePixelRatio || 1;
  const w = Math.max(1, Math.round(canvas.clientWidth));
  const h = Math.max(1, Math.round(canvas.clientHeight));
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  const ctx = canvas.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  return { ctx, w, h };
}

// A uniform world->screen map fitting the box [u0,u1]x[v0,v1] (v up).
function fit(u0, u1, v0, v1, w, h) {
  const du = Math.max(u1 - u0, 1e-6);
  const dv = Math.max(v1 - v0, 1e-6);
  const scale = Math.min((w - 2 * MARGIN_PX) / du, (h - 2 * MARGIN_PX) / dv);
  const cu = (u0 + u1) / 2;
  const cv = (v0 + v1) / 2;
  return {
    scale,
    x: (u) => w / 2 + (u - cu) * scale,
    y: (v) => h / 2 - (v - cv) * scale,
  };
}

// A 1, 2 or 5 x 10^k length about a fifth of the width, drawn bottom-left.
function scaleBar(ctx, map, w, h, unit) {
  const target = (w / 5) / map.scale;
  const p = Math.pow(10, Math.floor(Math.log10(target)));
  const len = [5, 2, 1].map((m) => m * p).find((l) => l <= target) || p;
  const px = len * map.scale;
  const y = h - 10;
  ctx.strokeStyle = INK;
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(10, y - 4);
  ctx.lineTo(10, y);
  ctx.lineTo(10 + px, y);
  ctx.lineTo(10 + px, y - 4);
  ctx.stroke();
  ctx.fillStyle = INK;
  ctx.font = '12px system-ui, sans-serif';
  ctx.fillText(`${+len.toPrecision(3)} ${unit}`, 14 + px, y);
}

function message(ctx, w, h, text) {
  ctx.fillStyle = '#555';
  ctx.font = '14px system-ui, sans-serif';
  ctx.textAlign = 'center';
  ctx.fillText(text, w / 2, h / 2);
  ctx.textAlign = 'start';
}

// Polyline of `pts` in screen space, coloured per point, broken at segments.
function path(ctx, pts, sx, sy) {
  ctx.lineWidth = 2;
  for (let i = 1; i < pts.length; i++) {
    if (pts[i].segment !== pts[i - 1].segment) continue;
    ctx.strokeStyle = QUALITY_COLOURS[pts[i].kind] || QUALITY_COLOURS.KIND_UNSPECIFIED;
    ctx.beginPath();
    ctx.moveTo(sx(pts[i - 1]), sy(pts[i - 1]));
    ctx.lineTo(sx(pts[i]), sy(pts[i]));
    ctx.stroke();
  }
  if (pts.length) {
    const last = pts[pts.length - 1];
    ctx.fillStyle = INK;
    ctx.beginPath();
    ctx.arc(sx(last), sy(last), 4, 0, 2 * Math.PI);
    ctx.fill();
  }
}

// The stretch of a near-vertical plane's line (n_x x + n_z z = d - n_y y)
// next to the poses that saw it: the poses' feet on the line, first to last.
function planeSegment(plane, pts) {
  const n = plane.normal;
  const n2 = n.x * n.x + n.z * n.z;
  if (n2 < 0.75) return null;  // not vertical enough to be a line top-down
  let lo = Infinity;
  let hi = -Infinity;
  let base = null;
  for (const p of pts) {
    if (p.segment !== plane.segment || p.t < plane.first_seen_s || p.t > plane.last_seen_s) continue;
    const r = (n.x * p.x + n.y * p.y + n.z * p.z - plane.distance) / n2;
    const fx = p.x - r * n.x;
    const fz = p.z - r * n.z;
    if (!base) base = { x: fx, z: fz };
    const along = (fx - base.x) * -n.z + (fz - base.z) * n.x;
    lo = Math.min(lo, along);
    hi = Math.max(hi, along);
  }
  if (!base) return null;
  const dir = { x: -n.z, z: n.x };
  return [
    { x: base.x + lo * dir.x, z: base.z + lo * dir.z },
    { x: base.x + hi * dir.x, z: base.z + hi * dir.z },
  ];
}

// points: [{t, x, y, z, kind, segment}], planes: [{normal, distance, first_seen_s, last_seen_s, segment}]
export function drawTopDown(canvas, points, planes, unit) {
  const { ctx, w, h } = context(canvas);
  if (!points.length) return message(ctx, w, h, 'no poses yet');
  const lines = planes.map((pl) => planeSegment(pl, points)).filter(Boolean);
  const us = points.map((p) => p.x).concat(lines.flat().map((q) => q.x));
  const vs = points.map((p) => p.z).concat(lines.flat().map((q) => q.z));
  const map = fit(Math.min(...us), Math.max(...us), Math.min(...vs), Math.max(...vs), w, h);
  ctx.strokeStyle = PLANE_COLOUR;
  ctx.lineWidth = 3;
  for (const [a, b] of lines) {
    ctx.beginPath();
    ctx.moveTo(map.x(a.x), map.y(a.z));
    ctx.lineTo(map.x(b.x), map.y(b.z));
    ctx.stroke();
  }
  path(ctx, points, (p) => map.x(p.x), (p) => map.y(p.z));
  scaleBar(ctx, map, w, h, unit);
  return lines.length;
}

// Height (−y) against the distance driven; ground planes (normal near ±y)
// drawn dashed under the poses that saw them.
export function drawSide(canvas, points, planes, unit) {
  const { ctx, w, h } = context(canvas);
  if (!points.length) return message(ctx, w, h, 'no poses yet');
  let s = 0;
  const pts = points.map((p, i) => {
    if (i > 0 && p.segment === points[i - 1].segment) {
      const q = points[i - 1];
      s += Math.hypot(p.x - q.x, p.z - q.z);
    }
    return { ...p, s, hgt: -p.y };
  });
  const grounds = [];
  for (const pl of planes) {
    if (Math.abs(pl.normal.y) < 0.7) continue;
    const g = pts
      .filter((p) => p.segment === pl.segment && p.t >= pl.first_seen_s && p.t <= pl.last_seen_s)
      .map((p) => ({ s: p.s, hgt: (pl.distance - pl.normal.x * p.x - pl.normal.z * p.z) / -pl.normal.y }));
    if (g.length > 1) grounds.push(g);
  }
  const hs = pts.map((p) => p.hgt).concat(grounds.flat().map((g) => g.hgt));
  const map = fit(0, Math.max(s, 1e-6), Math.min(...hs), Math.max(...hs), w, h);
  ctx.strokeStyle = PLANE_COLOUR;
  ctx.setLineDash([6, 4]);
  ctx.lineWidth = 2;
  for (const g of grounds) {
    ctx.beginPath();
    g.forEach((q, i) => (i ? ctx.lineTo(map.x(q.s), map.y(q.hgt)) : ctx.moveTo(map.x(q.s), map.y(q.hgt))));
    ctx.stroke();
  }
  ctx.setLineDash([]);
  path(ctx, pts, (p) => map.x(p.s), (p) => map.y(p.hgt));
  scaleBar(ctx, map, w, h, unit);
}

// Time series [{colour, values: [{t, v}]}], each scaled to its own maximum.
export function drawSeries(canvas, series) {
  const { ctx, w, h } = context(canvas);
  const all = series.flatMap((s) => s.values);
  if (all.length < 2) return message(ctx, w, h, 'collecting statistics…');
  const t0 = Math.min(...all.map((p) => p.t));
  const t1 = Math.max(...all.map((p) => p.t));
  for (const s of series) {
    const top = Math.max(...s.values.map((p) => p.v), 1e-9);
    ctx.strokeStyle = s.colour;
    ctx.lineWidth = 2;
    ctx.beginPath();
    s.values.forEach((p, i) => {
      const x = 8 + ((p.t - t0) / Math.max(t1 - t0, 1e-9)) * (w - 16);
      const y = h - 8 - (p.v / top) * (h - 24);
      return i ? ctx.lineTo(x, y) : ctx.moveTo(x, y);
    });
    ctx.stroke();
    const last = s.values[s.values.length - 1];
    ctx.fillStyle = s.colour;
    ctx.font = '12px system-ui, sans-serif';
    ctx.fillText(`${s.name} ${last ? last.v.toFixed(s.digits) : ''} (max ${top.toFixed(s.digits)})`, 8, 14 + 14 * series.indexOf(s));
  }
}
