// The scene picker's sizes: the server has no call that lists its built-in
// scenes with their sizes or descriptions, so the picker shows what the
// server said when this browser last built each one (Session.stats from
// CreateSession: control cells and points, cells at the level built),
// remembered in localStorage; a scene not built here yet says so.

export const SCENE_STATS_KEY = 'dynsolid.scenes';

const count = (n) => (n >= 1e4 ? `${(n / 1e3).toFixed(0)}k` : n >= 1e3 ? `${(n / 1e3).toFixed(1)}k` : String(n));

// What is kept of a Session's stats.
export function keepStats(stats) {
  const s = stats || {};
  return { control_cells: s.control_cells || 0, control_vertices: s.control_vertices || 0,
    levels: s.levels || 0, cells: s.cells || 0, boundary_faces: s.boundary_faces || 0,
    model: s.model || '' };
}

// The option's text: "chair · 4.8k cells" (or the bare name).
export function optionText(name, kept) {
  return kept ? `${name} · ${count(kept.cells)} cells` : name;
}

// The line under the picker.
export function aboutText(name, kept) {
  if (!kept) return `${name}: not built in this browser yet; its size shows once it is`;
  return `${name} as last built here: ${kept.control_cells} control cells, ${kept.control_vertices} control points; ` +
    `${count(kept.cells)} cells and ${count(kept.boundary_faces)} surface quads at level ${kept.levels}` +
    (kept.model ? `, ${kept.model}` : '');
}

export class ScenePicker {
  constructor(select, about) {
    this.select = select;
    this.about = about;
    this.select.addEventListener('change', () => this.refresh());
    this.refresh();
  }

  load() {
    try {
      return JSON.parse(localStorage.getItem(SCENE_STATS_KEY) || '{}') || {};
    } catch (e) {
      return {};
    }
  }

  // After CreateSession of built-in `name`: its stats.
  remember(name, stats) {
    const all = this.load();
    all[name] = keepStats(stats);
    try {
      localStorage.setItem(SCENE_STATS_KEY, JSON.stringify(all));
    } catch (e) {
      // storage blocked: shown until the page closes
    }
    this.memory = all;
    this.refresh();
  }

  refresh() {
    const all = this.memory || this.load();
    for (const o of this.select.options) o.textContent = optionText(o.value, all[o.value]);
    this.about.textContent = aboutText(this.select.value, all[this.select.value]);
  }
}
