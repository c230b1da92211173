// The paper's rule for the tool colour, f = |F| / forceUnitN with F in N:
// (R, G, B) = (min(0.2 + f, 1), max(0.2 - f, 0), max(0.2 - f, 0)), each in [0, 1].
// The same as force_colour in web/observer_state.cpp and the VTK viewer.
export function forceColour(forceN, forceUnitN = 1) {
  const f = Number.isFinite(forceN) ? Math.abs(forceN) / forceUnitN : 1;
  return [Math.min(0.2 + f, 1), Math.max(0.2 - f, 0), Math.max(0.2 - f, 0)];
}
