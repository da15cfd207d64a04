// The status line: a short line that fits a 1280 px window (the side
// panel takes 290 px) and the full one for its tooltip. Pure: the app
// passes what it knows.

// The model's short name ("corotational_cells" -> "corotational").
const shortModel = (m) => String(m || '').replace(/_cells$/, '').replace(/_/g, ' ');

const k = (n) => (n >= 10000 ? `${(n / 1000).toFixed(0)}k` : String(n));

// {short, full} from {connected, session: {id}, info (Session), stats
// (SessionStats or null), reconnecting, latency (ms or null), idle, fps,
// skipped, vertices}.
export function statusText(s) {
  const short = [];
  const full = [];
  if (!s.connected) {
    short.push('gateway: disconnected');
    full.push('gateway: disconnected');
  }
  if (!s.session) {
    short.push('no session: create one or join one');
    full.push('no session: create one or join one');
    return { short: short.join(' · '), full: full.join(' · ') };
  }
  const info = s.info || {};
  const st = info.stats || {};
  short.push(info.scene_name || '?');
  full.push(`${info.scene_name || '?'} ${s.session.id.slice(0, 8)}`);
  if (st.model) {
    const sub = st.substeps > 1 ? ` ×${st.substeps}` : '';
    short.push(`${shortModel(st.model)}${sub}`);
    full.push(`${st.model} / ${st.integrator}${sub}`);
  }
  const t = s.stats;
  if (t) {
    const rtf = (t.steps_per_second || 0) * (t.time_step || 0);
    const paused = t.paused ? ' (paused)' : '';
    short.push(`step ${t.step}${paused}`);
    if (!t.paused) short.push(`real time ×${rtf.toFixed(2)}`);
    short.push(`${(t.step_ms_median || 0).toFixed(1)} ms/step`);
    full.push(`step ${t.step}${paused}`, `${(t.steps_per_second || 0).toFixed(0)} steps/s`,
      `real time ×${rtf.toFixed(2)}`, `step ${(t.step_ms_median || 0).toFixed(1)} ms`);
  } else if (s.reconnecting) {
    short.push('server unavailable');
    full.push('server unavailable');
  }
  const lat = s.latency === null || s.latency === undefined ? '–' : `${s.latency.toFixed(0)} ms`;
  short.push(`cmd ${lat}`);
  full.push(`command ${lat}`);
  const fps = s.idle ? 'idle' : `${s.fps.toFixed(0)} fps`;
  short.push(fps);
  full.push(s.idle ? 'idle (nothing moved)' : fps, `${s.skipped} skipped`);
  short.push(`${k(s.vertices)} vertices`);
  full.push(`${s.vertices} vertices`);
  return { short: short.join(' · '), full: full.join(' · ') };
}
