// Live plot of each station's force magnitude |F| (N) over the last WINDOW_S seconds, one line
// per station, on a 2D canvas. Samples are timed when they reach the page.
const WINDOW_S = 10;
const COLOURS = ['#4fc3f7', '#ffb74d', '#81c784', '#e57373', '#ba68c8', '#fff176'];

export class ForcePlot {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.series = new Map();  // station id → { colour, samples: [[t_s, force_n]] }
    this.pending = false;
  }

  colourOf(station) {
    let s = this.series.get(station);
    if (!s) {
      s = { colour: COLOURS[this.series.size % COLOURS.length], samples: [] };
      this.series.set(station, s);
    }
    return s.colour;
  }

  add(station, forceN) {
    this.colourOf(station);
    const t = performance.now() / 1000;
    const s = this.series.get(station);
    s.samples.push([t, forceN]);
    while (s.samples.length && s.samples[0][0] < t - WINDOW_S) s.samples.shift();
    if (!this.pending) {
      this.pending = true;
      requestAnimationFrame(() => { this.pending = false; this.draw(); });
    }
  }

  draw() {
    const { ctx, canvas } = this;
    const w = canvas.width, h = canvas.height, left = 36, bottom = 16;
    const now = performance.now() / 1000;
    let top = 0.1;
    for (const s of this.series.values()) for (const [, f] of s.samples) top = Math.max(top, f * 1.15);
    ctx.clearRect(0, 0, w, h);
    ctx.font = '10px system-ui, sans-serif';
    ctx.strokeStyle = '#2d313a';
    ctx.fillStyle = '#8a93a2';
    for (let i = 0; i <= 4; ++i) {
      const y = (h - bottom) * (1 - i / 4);
      ctx.beginPath(); ctx.moveTo(left, y); ctx.lineTo(w, y); ctx.stroke();
      ctx.fillText((top * i / 4).toPrecision(2), 2, Math.max(y, 9));
    }
    ctx.fillText(`N, last ${WINDOW_S} s`, left + 4, h - 4);
    for (const s of this.series.values()) {
      ctx.strokeStyle = s.colour;
      ctx.lineWidth = 1.5;
      ctx.beginPath();
      s.samples.forEach(([t, f], i) => {
        const x = left + (w - left) * (1 - (now - t) / WINDOW_S);
        const y = (h - bottom) * (1 - f / top);
        if (i === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
      });
      ctx.stroke();
    }
  }
}
