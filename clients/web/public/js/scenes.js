// The scene picker: what each built-in scene is for and its size, from the
// server's ListScenes when it has the call; otherwise what the server said
// when this browser last built each one (Session.stats from CreateSession:
// control cells and points, cells at the level built), remembered in
// localStorage, and a scene not built here yet says so.

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

// What the server says of a scene (ListScenes' entry): its size for the
// option, and what it is for under the picker.
export function serverOptionText(entry) {
  return `${entry.name} · ${count(Number(entry.cells) || 0)} cells`;
}
export function serverAboutText(entry) {
  const s = entry.size || {};
  const dims = [s.x, s.y, s.z].map((v) => {
    const m = Number(v) || 0;
    return m >= 1 ? m.toFixed(1) : m.toFixed(2);
  }).join(' x ');
  return `${entry.description} (${entry.control_cells} control cells, ${count(Number(entry.cells) || 0)} cells ` +
    `at level ${entry.levels}; ${dims} m)`;
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

  // The server's list (ListScenes): every scene it has, with what it is
  // for and its size; it wins over what this browser remembers. A server
  // without the call leaves the picker as it was.
  async fetch(conn) {
    try {
      const list = await conn.call('ListScenes', {});
      this.server = Object.fromEntries((list.scenes || []).map((e) => [e.name, e]));
    } catch (e) {
      return;
    }
    const have = new Set([...this.select.options].map((o) => o.value));
    for (const name of Object.keys(this.server)) {
      if (!have.has(name)) this.select.add(new Option(name, name));
    }
    this.refresh();
  }

  refresh() {
    const all = this.memory || this.load();
    const server = this.server || {};
    for (const o of this.select.options) {
      o.textContent = server[o.value] ? serverOptionText(server[o.value]) : optionText(o.value, all[o.value]);
      if (server[o.value]) o.title = server[o.value].description;
    }
    const chosen = this.select.value;
    this.about.textContent = server[chosen] ? serverAboutText(server[chosen]) : aboutText(chosen, all[chosen]);
  }
}
