// The paper's rule for the tool colour, f = |F| / forceUnitN with F in N: each channel is
// clamp(offset + slope * f, 0, 1), which with common/force_colour.hpp's numbers is
// (R, G, B) = (min(0.2 + f, 1), max(0.2 - f, 0), max(0.2 - f, 0)). The numbers come from that
// header: the build generates generated/force_colour_rule.js from it (web/colour_rule_js.cpp).
import { FORCE_COLOUR_RULE } from './generated/force_colour_rule.js';

export function forceColour(forceN, forceUnitN = 1) {
  const r = FORCE_COLOUR_RULE;
  const f = Number.isFinite(forceN) ? Math.abs(forceN) / forceUnitN : r.notFiniteF;
  return [0, 1, 2].map((k) => Math.min(Math.max(r.offset[k] + r.slope[k] * f, 0), 1));
}

// The rule as the page's note shows it, e.g. "(R,G,B) = (min(0.2+f,1), max(0.2−f,0), ...)".
export function describeRule() {
  const r = FORCE_COLOUR_RULE;
  const channel = (k) => {
    const s = r.slope[k];
    const term = s === 0 ? '' : `${s > 0 ? '+' : '\u2212'}${Math.abs(s) === 1 ? '' : Math.abs(s)}f`;
    const v = `${r.offset[k]}${term}`;
    if (s > 0) return `min(${v},1)`;
    if (s < 0) return `max(${v},0)`;
    return v;
  };
  return `(R,G,B) = (${channel(0)}, ${channel(1)}, ${channel(2)})`;
}
