// Refusals in plain words: the server's common messages as a sentence and
// what to do. The server's exact text stays with them (the banner's
// details line and title), for logs, tests and bug reports.

const RULES = [
  // Undo and redo (per person, last first; the History panel). First: the
  // entry's name may be "merge faces 3 and 5" and so on.
  [/command\.undo: you have nothing to undo/,
    'You have nothing to undo.', 'Undo takes back only your own actions; others\' stay.'],
  [/command\.redo: you have nothing to redo/,
    'You have nothing to redo.', 'Redo brings back what you undid, until you do something new.'],
  [/command\.undo: cannot undo .*Nothing changed/,
    'A later change builds on that one, so Undo cannot take it back yet; nothing changed.',
    'That change has to be undone first (the History panel shows whose it is).'],
  [/command\.redo: cannot redo .*Nothing changed/,
    'The session changed since, so Redo cannot bring that back; nothing changed.',
    'Undo the later change first, or do it again by hand.'],
  // Downloads (Export).
  [/export limit|request\.level: -?\d+ is not in/i,
    'That level is too fine to export for this solid.', 'Pick a lower level in the Download menu.'],
  [/request\.format/i,
    'The server does not write that file format.', 'Pick another format in the Download menu.'],
  [/request\.color_field/i,
    'The server cannot colour the file by that field.', 'Download it without colours.'],
  [/^UNIMPLEMENTED .*\bExport\b/,
    'This server cannot make downloads yet.', 'Update dynsolid-server and the gateway.'],
  [/^CANCELLED .*(download|cancelled by the page)/i,
    'The download was cancelled.', ''],
  [/during the download/i,
    'The connection to the server broke during the download.', 'Download it again once the page is live.'],
  [/scene_text|scene file/i,
    'The scene file has an error; nothing was created.', 'Fix the line named below and load the file again.'],
  [/cells must have positive volume|zero volume|negative volume|elements are inverted at rest|too distorted/i,
    'That edit would fold a cell flat or inside out.',
    'Undo the last pull or bend, let the solid settle, or extrude a shorter distance.'],
  [/only boundary faces merge|is interior \(shared by cells/i,
    'Merge joins faces on the outside of the solid only.',
    'Click two faces you can see, facing each other across a gap.'],
  [/merge needs equal counts/i,
    'Those two faces have different shapes (different corner counts).',
    'Pick two faces of the same kind, facing each other.'],
  [/connecting cell would be degenerate|share vertex/i,
    'Those faces touch; there is no gap between them to bridge.',
    'Pick two faces with a gap between them.'],
  [/merge needs two distinct faces|with itself/i,
    'Merge needs two different faces.', 'Click the first face, then another one.'],
  [/merge/i,
    'Merge could not join those faces.',
    'Pick two faces that face each other across a gap (a handle or a bridge).'],
  [/extrude them separately|normals cancel/i,
    'Those faces point in opposite directions, so there is no single way out.',
    'Extrude one face at a time.'],
  [/would leave nothing/i,
    'That would delete the whole solid.', 'Keep at least one cell.'],
  [/is not an edge of the control mesh|sharp edge/i,
    'No control edge there to make sharp.', 'Turn on "control mesh" and click close to a drawn edge.'],
  [/selects no boundary face/i,
    'The brush covers no part of the surface there.', 'Make the radius bigger (]) or press on the solid.'],
  [/yield|COROTATIONAL/i,
    'This session\'s material model cannot hold clay.',
    'Create the session with Model: corotational (the built-in sculpting scenes use it).'],
  [/pressure acts|while a box or sphere pressure/i,
    'Bake waits until no pressure is held.', 'Release Inflate or Deflate, then Bake again.'],
  [/^RESOURCE_EXHAUSTED/,
    'The server is busy with your earlier commands.', 'Wait a moment and try again.'],
  [/^NOT_FOUND/,
    'The session is gone (closed, or the server lost it).', 'Create a new session or join another.'],
  [/^PERMISSION_DENIED/,
    'This link\'s token does not open the session.', 'Ask for the share link again.'],
];

// {text, hint, detail} for an error from the connection (err.codeName,
// err.message) or any Error; unknown messages get a generic sentence.
export function explain(err) {
  const message = String((err && err.message) || err);
  const code = err && err.codeName;
  const detail = code ? `refused (${code}): ${message}` : message;
  const haystack = `${code || ''} ${message}`;
  for (const [re, text, hint] of RULES) {
    if (re.test(haystack)) return { text, hint, detail };
  }
  if (code) return { text: 'The server refused that.', hint: 'The details below say why.', detail };
  return { text: message, hint: '', detail: '' };
}
