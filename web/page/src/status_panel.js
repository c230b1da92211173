// The side panel and the banner over the view: connection, the server's status (scene, tier,
// rates, step times), the stations with their force, and what is wrong when something is.

function fmt(v, digits = 1, unit = '') {
  if (v === null || v === undefined || !Number.isFinite(v)) return '–';
  return `${v.toFixed(digits)}${unit ? ` ${unit}` : ''}`;
}

function element(tag, text, cls) {
  const e = document.createElement(tag);
  if (text !== undefined) e.textContent = text;
  if (cls) e.className = cls;
  return e;
}

export class StatusPanel {
  constructor(doc) {
    this.connection = doc.getElementById('connection');
    this.server = doc.getElementById('server');
    this.stations = doc.getElementById('stations');
    this.banner = doc.getElementById('banner');
  }

  // The banner shows the first problem: no connection, refused, server away, no scene yet.
  showBanner(text) {
    this.banner.hidden = !text;
    this.banner.textContent = text || '';
  }

  setConnection(state, detail, framesPerS) {
    this.connection.replaceChildren(
      element('span', state === 'open' ? 'connected' : state, state === 'open' ? 'ok' : 'bad'),
      element('span', detail ? ` – ${detail}` : state === 'open'
        ? ` – ${fmt(framesPerS, 0)} deformation frames/s per mesh` : ''));
  }

  setStatus(status) {
    const rows = [];
    const s = status && status.server;
    rows.push(['server', status ? (status.server_alive ? 'alive' : 'away (last state kept)') : '–',
      status && status.server_alive ? 'ok' : 'bad']);
    if (s) {
      rows.push(['id / scene', `${s.server_id} / ${s.scene}`]);
      rows.push(['tier', s.tier_update_rate_hz > 0
        ? `${s.tier}, equilibrium ${fmt(s.tier_update_rate_hz, 1, 'Hz')}` : s.tier]);
      rows.push(['step rate', `${fmt(s.step_rate_measured_hz, 0)} / ${fmt(s.step_rate_target_hz, 0, 'Hz')}`]);
      rows.push(['step time', `p50 ${fmt(s.step_time_p50_us, 0)}, p99 ${fmt(s.step_time_p99_us, 0, 'µs')}`]);
      rows.push(['deformation', `${fmt(status.bridge.deformation_hz, 1)} / ${fmt(s.viewer_rate_hz, 0, 'Hz')}`]);
      // Accuracy at the strain reached (-1: not measured / unknown): the total against the
      // converged answer (nested refinements extrapolated) and its parts, mesh + element and tier.
      if (s.max_strain >= 0) rows.push(['max strain', fmt(100 * s.max_strain, 1, '%')]);
      const pct = (v) => (v >= 0 ? `~${fmt(100 * v, 1, '%')}` : 'unknown');
      rows.push(['error vs converged answer', `${pct(s.total_error_estimate)} (mesh + element ` +
        `${pct(s.discretization_error_estimate)}, tier ${s.max_strain >= 0
          ? pct(s.expected_force_error) : 'not measured'})`]);
      rows.push(['effects', s.effects || '–']);
      rows.push(['uptime', fmt(s.uptime_s, 0, 's')]);
      rows.push(['deadline misses', String(s.deadline_misses)]);
      // Contact nodes a step needed before the column worker had solved them (each took the
      // step's fallback), summed since the server started: 0 while the worker keeps ahead.
      if (s.columns_not_ready !== undefined) rows.push(['columns not ready', String(s.columns_not_ready)]);
      // Steps that did not solve the whole contact (rows beyond the per-tool limit left out; the
      // LCP not converged, the last good answer kept), since the server started: 0 normally.
      if (s.steps_with_rows_dropped !== undefined) {
        rows.push(['contact rows dropped', `${s.steps_with_rows_dropped} steps`,
          s.steps_with_rows_dropped > 0 ? 'bad' : 'ok']);
      }
      if (s.steps_not_converged !== undefined) {
        rows.push(['contact not converged', `${s.steps_not_converged} steps`,
          s.steps_not_converged > 0 ? 'bad' : 'ok']);
      }
    }
    if (status) rows.push(['observers', `${status.bridge.clients} of ${status.bridge.max_clients}`]);
    this.server.replaceChildren(...rows.flatMap(([k, v, cls]) => [element('dt', k), element('dd', v, cls)]));
  }

  setStations(stations, colourOf, forceUnitN) {
    this.stations.replaceChildren(...stations.map((s) => {
      const li = element('li');
      const sw = element('span', '', 'swatch');
      sw.style.background = colourOf(s.id);
      li.append(sw, element('span',
        `${s.id}: ${fmt(s.force_magnitude_n, 3, 'N')}${s.in_contact ? ` on ${s.mesh}` : ''} ` +
        `(f = ${fmt(s.force_magnitude_n / forceUnitN, 2)})`));
      return li;
    }));
  }
}
