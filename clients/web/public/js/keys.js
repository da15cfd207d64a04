// The keyboard and the wheel with a modifier (docs/viewer.md lists them):
// undo/redo, Esc, `[`/`]` brush size (shift: strength), view presets and
// framing.

import * as C from './commands.js';
import { KNOBS } from './sizing.js';

// Keys (KeyboardEvent.key or .code) -> view preset.
export const VIEW_KEYS = {
  1: 'front', Numpad1: 'front', 3: 'side', Numpad3: 'side', 7: 'top', Numpad7: 'top',
  0: 'iso', Numpad0: 'iso', f: 'frame', F: 'frame', NumpadDecimal: 'frame',
};

// What a key press does, as {action, ...}, or null (pure, for the tests).
export function keyAction(e) {
  const k = e.key;
  const mod = e.ctrlKey || e.metaKey;
  if (mod && k.toLowerCase() === 'z') return { action: e.shiftKey ? 'redo' : 'undo' };
  if (mod && k.toLowerCase() === 'y') return { action: 'redo' };
  if (mod || e.altKey) return null;
  if (k === 'Escape') return { action: 'cancel' };
  if (k === '?') return { action: 'help' };
  if (e.code === 'BracketLeft' || e.code === 'BracketRight' || (k.length === 1 && '[]{}'.includes(k))) {
    const bigger = e.code === 'BracketRight' || k === ']' || k === '}';
    return { action: 'nudge', which: e.shiftKey ? 'strength' : 'size', steps: bigger ? 1 : -1 };
  }
  const preset = VIEW_KEYS[e.code && e.code.startsWith('Numpad') ? e.code : k];
  if (preset) return { action: 'look', preset };
  return null;
}

export function bindKeys(app) {
  window.addEventListener('keydown', (e) => {
    const t = e.target;
    if ((t.tagName === 'INPUT' && t.type !== 'checkbox') || t.tagName === 'SELECT' || t.tagName === 'TEXTAREA') return;
    const a = keyAction(e);
    if (!a) return;
    e.preventDefault();
    switch (a.action) {
      case 'undo': app.send(C.undo(), 'undo'); break;
      case 'redo': app.send(C.redo(), 'redo'); break;
      case 'cancel':
        if (app.help.isOpen) app.help.close();
        else app.tools.cancel();
        break;
      case 'help': app.help.toggle(); break;
      case 'nudge': app.nudge(a.which, a.steps); break;
      case 'look': app.look(a.preset); break;
      default: break;
    }
  });
}

// The wheel over the canvas with Ctrl, Alt or Meta held: the brush size
// (with shift: the strength), half a step per notch. Returns whether it
// took the event.
export function wheelNudge(app, e) {
  if (!(e.ctrlKey || e.altKey || e.metaKey) || !KNOBS[app.tools.tool]) return false;
  const d = e.deltaY || e.deltaX;  // shift+wheel scrolls sideways in some browsers
  if (!d) return true;
  app.nudge(e.shiftKey ? 'strength' : 'size', d < 0 ? 0.5 : -0.5);
  return true;
}
