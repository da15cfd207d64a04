#!/usr/bin/env node
// Validates a glTF 2.0 file (.glb or .gltf) with the Khronos glTF validator
// (npm gltf-validator, pinned by package-lock.json; `npm ci` here, which
// scripts/setup_web.sh runs). Used by tests/io/io_export_test.cc.
//
//   node tests/io/gltf/validate.mjs FILE.glb
//
// Prints the validator's report (JSON) and exits 0 when it has no errors,
// 1 when it has errors, 2 when the file cannot be read or validated at all.
import { readFile } from 'node:fs/promises';
import { basename } from 'node:path';
import validator from 'gltf-validator';

async function main() {
  const file = process.argv[2];
  if (!file || process.argv.length > 3) {
    console.error('usage: node validate.mjs FILE.glb');
    return 2;
  }
  let bytes;
  try {
    bytes = new Uint8Array(await readFile(file));
  } catch (e) {
    console.error(`validate.mjs: cannot read ${file}: ${e.message}`);
    return 2;
  }
  let report;
  try {
    report = await validator.validateBytes(bytes, {
      uri: basename(file),
      maxIssues: 0,  // report every issue
      writeTimestamp: false,
    });
  } catch (e) {
    console.error(`validate.mjs: the validator could not process ${file}: ${e}`);
    return 2;
  }
  console.log(JSON.stringify(report, null, 2));
  const issues = report.issues;
  console.log(`validate.mjs: ${file}: ${issues.numErrors} errors, ${issues.numWarnings} warnings, ` +
              `${issues.numInfos} infos, ${issues.numHints} hints (gltf-validator ${validator.version()})`);
  return issues.numErrors > 0 ? 1 : 0;
}

process.exitCode = await main();
