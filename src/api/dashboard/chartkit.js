// Chart kit: the uPlot plugins the charts share — error bars (± 1 standard error), shaded bands
// around a line (± 1 SE), point markers that are filled or open (a value with or without a
// standard error of its own), guide lines (a vertical marker such as r₃ = a, a horizontal
// reference such as the quadrature luminance) and edge marks (a value beyond the y range, marked
// ▲/▼ at the frame's edge with its value) — and the y range that keeps all of them in view.
//
// A chart's extras live on its PlotSlot (plots.js), indexed like the y series (null: none for that
// series), so that a redraw with new data needs no new plugin and the chart files (chartsvg.js) can
// draw the same things:
//   slot.bars    [{ err: [...], color }]       error bars of series s + 1
//   slot.bands   [{ lo: [...], hi: [...], color }]  a shaded band under series s + 1
//   slot.markers [{ open: [...], color }]      a marker at every value of series s + 1, open where
//                                              open[i] (the series itself then shows no points)
//   slot.guides  { x: [{ value, label }], y: [{ value, label }] }
//   slot.edges   [{ s, i, x, value, text, color }]  values of series s + 1 beyond the y range
//                                              (null in the series' data), marked at the edge
//   slot.notes   [{ marker, text }]            legend lines of the chart files beside the series
//                                              (marker: 'filled', 'open', 'edge' or 'none')
// Every plugin writes what it drew to the container's data attributes (the browser test reads
// them): data-error-bars, data-bands, data-markers, data-open-markers, data-guides, data-off-scale.

/* global uPlot */

/** A colour with transparency: '#1f77b4' → 'rgba(31, 119, 180, alpha)'. */
export function withAlpha(color, alpha) {
  const m = /^#([0-9a-f]{2})([0-9a-f]{2})([0-9a-f]{2})$/i.exec(color);
  if (!m) return color;
  return `rgba(${m.slice(1).map((c) => parseInt(c, 16)).join(', ')}, ${alpha})`;
}

/**
 * Draws a vertical bar of ± err around every value of the series in `slot.bars` (by series, with
 * its colour), clipped to the plot; on a log scale a bar reaching zero runs to the bottom edge.
 */
export function errorBars(slot) {
  const draw = (u) => {
    const { ctx } = u;
    const { left, top, width, height } = u.bbox;
    const log = u.scales.y.distr === 3;
    const cap = 3 * devicePixelRatio;
    let drawn = 0;
    ctx.save();
    ctx.beginPath();
    ctx.rect(left, top, width, height);
    ctx.clip();
    ctx.lineWidth = devicePixelRatio;
    ctx.setLineDash([]);
    (slot.bars ?? []).forEach((bar, s) => {
      if (!bar || !u.series[s + 1]?.show) return;
      const { err, color } = bar;
      ctx.strokeStyle = color;
      ctx.beginPath();
      err.forEach((e, i) => {
        const y = u.data[s + 1][i];
        if (y === null || e === null || !(e > 0)) return;
        const x = u.valToPos(u.data[0][i], 'x', true);
        const hi = u.valToPos(y + e, 'y', true);
        const floor = log && y - e <= 0;
        const lo = floor ? top + height : u.valToPos(y - e, 'y', true);
        ctx.moveTo(x, lo);
        ctx.lineTo(x, hi);
        ctx.moveTo(x - cap, hi);
        ctx.lineTo(x + cap, hi);
        if (!floor) {
          ctx.moveTo(x - cap, lo);
          ctx.lineTo(x + cap, lo);
        }
        drawn += 1;
      });
      ctx.stroke();
    });
    ctx.restore();
    slot.container.dataset.errorBars = drawn;
  };
  return { hooks: { draw: [draw] } };
}

/** The radius of a marker of `markers`, in CSS pixels. */
export const MARKER_RADIUS = 3;

/**
 * Draws `slot.markers`: a filled disc at every value of the series, or an open circle where
 * `open[i]` (a value without a standard error of its own, e.g. a smoothed cell), over the lines.
 */
export function markers(slot) {
  const draw = (u) => {
    const { ctx } = u;
    const { left, top, width, height } = u.bbox;
    const radius = MARKER_RADIUS * devicePixelRatio;
    let filled = 0;
    let open = 0;
    ctx.save();
    ctx.beginPath();
    ctx.rect(left, top, width, height);
    ctx.clip();
    ctx.lineWidth = 1.5 * devicePixelRatio;
    ctx.setLineDash([]);
    (slot.markers ?? []).forEach((marker, s) => {
      if (!marker || !u.series[s + 1]?.show) return;
      const { open: isOpen, color } = marker;
      u.data[s + 1].forEach((y, i) => {
        if (y === null || y === undefined) return;
        const x = u.valToPos(u.data[0][i], 'x', true);
        const py = u.valToPos(y, 'y', true);
        ctx.beginPath();
        ctx.arc(x, py, radius, 0, 2 * Math.PI);
        if (isOpen[i]) {
          ctx.fillStyle = '#fff';
          ctx.fill();
          ctx.strokeStyle = color;
          ctx.stroke();
          open += 1;
        } else {
          ctx.fillStyle = color;
          ctx.fill();
          filled += 1;
        }
      });
    });
    ctx.restore();
    slot.container.dataset.markers = filled + open;
    slot.container.dataset.openMarkers = open;
  };
  return { hooks: { draw: [draw] } };
}

/** Shades `slot.bands` (lo to hi, per shown series) under the lines: drawn after the axes, before the series. */
export function bands(slot) {
  const draw = (u) => {
    const { ctx } = u;
    const { left, top, width, height } = u.bbox;
    let drawn = 0;
    ctx.save();
    ctx.beginPath();
    ctx.rect(left, top, width, height);
    ctx.clip();
    (slot.bands ?? []).forEach(({ lo, hi, color }, s) => {
      if (!u.series[s + 1]?.show) return;
      ctx.fillStyle = withAlpha(color, 0.14);
      for (const run of runs(lo, hi)) {
        ctx.beginPath();
        run.forEach((i, k) => {
          const x = u.valToPos(u.data[0][i], 'x', true);
          const y = u.valToPos(hi[i], 'y', true);
          if (k === 0) ctx.moveTo(x, y);
          else ctx.lineTo(x, y);
        });
        for (const i of [...run].reverse()) ctx.lineTo(u.valToPos(u.data[0][i], 'x', true), u.valToPos(lo[i], 'y', true));
        ctx.closePath();
        ctx.fill();
      }
      drawn += 1;
    });
    ctx.restore();
    slot.container.dataset.bands = drawn;
  };
  return { hooks: { drawAxes: [draw] } };
}

/** The index runs where both lo and hi are numbers (a band is broken at gaps). */
export function runs(lo, hi) {
  const out = [];
  let run = [];
  lo.forEach((l, i) => {
    if (l === null || hi[i] === null || !Number.isFinite(l) || !Number.isFinite(hi[i])) {
      if (run.length) out.push(run);
      run = [];
    } else {
      run.push(i);
    }
  });
  if (run.length) out.push(run);
  return out;
}

/** Dashed guide lines with their labels: `slot.guides.x` vertical, `slot.guides.y` horizontal. */
export function guides(slot) {
  const draw = (u) => {
    const { ctx } = u;
    const { left, top, width, height } = u.bbox;
    const drawn = [];
    ctx.save();
    ctx.lineWidth = 1.5 * devicePixelRatio;
    ctx.setLineDash([6 * devicePixelRatio, 4 * devicePixelRatio]);
    ctx.strokeStyle = '#333';
    ctx.fillStyle = '#333';
    ctx.font = `${12 * devicePixelRatio}px system-ui, sans-serif`;
    ctx.textAlign = 'left';
    ctx.textBaseline = 'alphabetic';
    for (const [axis, list] of [['x', slot.guides?.x ?? []], ['y', slot.guides?.y ?? []]]) {
      for (const { value, label } of list) {
        const p = u.valToPos(value, axis, true);
        const inside = axis === 'x' ? p >= left && p <= left + width : p >= top && p <= top + height;
        if (!Number.isFinite(p) || !inside) continue;
        ctx.beginPath();
        if (axis === 'x') {
          ctx.moveTo(p, top);
          ctx.lineTo(p, top + height);
        } else {
          ctx.moveTo(left, p);
          ctx.lineTo(left + width, p);
        }
        ctx.stroke();
        if (axis === 'x') ctx.fillText(label, p + 4 * devicePixelRatio, top + 14 * devicePixelRatio);
        else ctx.fillText(label, left + 6 * devicePixelRatio, p - 5 * devicePixelRatio);
        drawn.push(`${axis}=${value}`);
      }
    }
    ctx.restore();
    slot.container.dataset.guides = drawn.join(' ');
  };
  return { hooks: { draw: [draw] } };
}

/**
 * Where edgeMarks (and the chart files) put the marks of `edges` on a y range [min, max]: per value
 * beyond it its `side` ('top' above the range, 'bottom' below), its x position `px` (`xPos`), where
 * its label starts (`lx`, just left of the mark) and the `row` of its label. The labels lie inside
 * the frame beyond the triangles (which stay on the edge), so no triangle covers a label; one that
 * would overlap the label before it on the same edge moves to the next row (at most three, then the
 * least crowded); a label that would run past the frame's right end `right` ends there instead.
 * `gap`, `right` and `labelWidth` in the units of `xPos`.
 */
export function edgeLayout(edges, min, max, xPos, labelWidth, gap, right = Infinity) {
  const ends = { top: [], bottom: [] }; // per edge, the right end of the last label in each row
  return edges
    .filter((e) => e.value > max || e.value < min)
    .map((e) => ({ ...e, px: xPos(e.x) }))
    .filter((e) => Number.isFinite(e.px))
    .sort((a, b) => a.px - b.px)
    .map((e) => {
      const side = e.value > max ? 'top' : 'bottom';
      const rows = ends[side];
      const width = labelWidth(e.text);
      const lx = Math.min(e.px - gap, right - width);
      let row = rows.findIndex((end) => end + gap < lx);
      if (row < 0) row = rows.length < 3 ? rows.length : rows.indexOf(Math.min(...rows));
      rows[row] = lx + width;
      return { ...e, side, row, lx };
    });
}

/** How far from the frame's edge (CSS px) the centre of an edge mark's label in `row` lies: past the triangle. */
export const edgeLabelOffset = (row) => 16 + 13 * row;

/** The edge marks' text size in CSS px. */
export const EDGE_FONT = 11;

/**
 * Marks `slot.edges` — values of shown series beyond the y range, which the series' data leave out
 * (null) so that no line runs off the frame — as a triangle at the frame's edge, ▲ at the top for
 * a value above the range and ▼ at the bottom for one below, in the series' colour, with the value
 * as text just inside the frame past it (edgeLayout): an off-scale cell is seen with its value,
 * not silently clipped.
 */
export function edgeMarks(slot) {
  const draw = (u) => {
    const { ctx } = u;
    const { left, top, width, height } = u.bbox;
    const px = devicePixelRatio;
    const half = 5 * px;
    const shown = (slot.edges ?? []).filter((e) => u.series[e.s + 1]?.show);
    ctx.save();
    ctx.font = `${EDGE_FONT * px}px system-ui, sans-serif`;
    ctx.textBaseline = 'middle';
    ctx.textAlign = 'left';
    const layout = edgeLayout(shown, u.scales.y.min, u.scales.y.max, (x) => u.valToPos(x, 'x', true),
      (text) => ctx.measureText(text).width, 4 * px, left + width);
    for (const m of layout) {
      const down = m.side === 'bottom';
      const edge = down ? top + height - px : top + px;
      const base = down ? edge - 1.6 * half : edge + 1.6 * half;
      ctx.fillStyle = m.color;
      ctx.beginPath();
      ctx.moveTo(m.px, edge);
      ctx.lineTo(m.px - half, base);
      ctx.lineTo(m.px + half, base);
      ctx.closePath();
      ctx.fill();
      const offset = edgeLabelOffset(m.row) * px;
      ctx.fillStyle = '#1d2430';
      ctx.fillText(m.text, m.lx, down ? edge - offset : edge + offset);
    }
    ctx.restore();
    slot.container.dataset.offScale = layout.length;
    slot.container.dataset.offScaleText = layout.map((m) => m.text).join(' | ');
  };
  return { hooks: { draw: [draw] } };
}

/**
 * The lowest and highest value over the shown series of `u`, with their error bars and bands, and
 * the horizontal guides (lows ≤ 0 skipped when `log`); null when there is nothing.
 */
export function extent(u, slot, log) {
  let lo = Infinity;
  let hi = -Infinity;
  const take = (v) => {
    if (v === null || v === undefined || !Number.isFinite(v) || (log && v <= 0)) return;
    lo = Math.min(lo, v);
    hi = Math.max(hi, v);
  };
  u.data.slice(1).forEach((ys, s) => {
    if (u.series[s + 1] && !u.series[s + 1].show) return;
    ys.forEach((y, i) => {
      if (y === null || y === undefined) return;
      const e = slot.bars?.[s]?.err[i] ?? 0;
      take(log && y - e <= 0 ? y : y - e);
      take(y + e);
      const band = slot.bands?.[s];
      if (band) {
        take(band.lo[i]);
        take(band.hi[i]);
      }
    });
  });
  for (const { value } of slot.guides?.y ?? []) take(value);
  return Number.isFinite(lo) ? [lo, hi] : null;
}

/** A log scale around [lo, hi] (1 % to 100 % when there is nothing to show). */
export const logRange = (e) => (e ? uPlot.rangeLog(e[0], e[1], 10, false) : [1, 100]);

/** A linear scale around [lo, hi] with 5 % room on each side. */
export function linearRange(e) {
  if (!e) return [0, 1];
  const pad = e[0] === e[1] ? Math.abs(e[0]) * 0.1 || 1 : 0.05 * (e[1] - e[0]);
  return [e[0] - pad, e[1] + pad];
}
