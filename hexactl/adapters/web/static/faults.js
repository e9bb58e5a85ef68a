// The controller's latched faults as the page lists them: one line a code, since a link
// lost latches the same fault on all six legs at once and six lines alike push the
// controls out of view; then what to do next.

/**
 * ``faults`` (the telemetry's, in order) grouped by code, in the order each code first
 * came: {code, message and leg (the first fault's; leg null without one), otherLegs (the
 * group's other legs, ascending), all (every message, for the line's tooltip)}.
 */
export function groupFaults(faults) {
  const groups = new Map();
  for (const fault of Array.isArray(faults) ? faults : []) {
    const code = typeof fault?.code === 'string' ? fault.code : 'fault';
    const message = typeof fault?.message === 'string' ? fault.message : '';
    const leg = Number.isInteger(fault?.leg) ? fault.leg : null;
    if (!groups.has(code)) groups.set(code, { code, message, leg, otherLegs: [], all: [] });
    const group = groups.get(code);
    if (leg !== null && leg !== group.leg && !group.otherLegs.includes(leg)) group.otherLegs.push(leg);
    group.all.push(leg !== null ? `leg ${leg}: ${message}` : message);
  }
  return [...groups.values()].map((group) => ({ ...group, otherLegs: group.otherLegs.sort((a, b) => a - b) }));
}

/**
 * One group's line after its code: the first message, its leg and the group's other legs
 * (``(leg 3; also legs 1, 2)``), and how many more messages the tooltip has.
 */
export function faultLine(group) {
  const others = group.otherLegs;
  const also = others.length ? `; also leg${others.length > 1 ? 's' : ''} ${others.join(', ')}` : '';
  const legs = group.leg !== null ? ` (leg ${group.leg}${also})` : (also ? ` (${also.slice(2)})` : '');
  const more = group.all.length - 1 - others.length;  // repeats on no other leg (E-stops, one per press)
  return `${group.message}${legs}${more > 0 ? `, and ${more} more` : ''}`;
}

/** What the operator does next in the controller's ``state``; '' where nothing is latched. */
export function faultAdvice(state) {
  if (state === 'estop') return 'Once the cause of the E-stop is gone: Reset (the controller ends disabled), then Enable.';
  if (state === 'fault') return 'Remove the cause, then Reset (the controller ends disabled), then Enable.';
  return '';
}
