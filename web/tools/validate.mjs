// Validates glTF 2.0 files with the Khronos glTF-Validator (npm `gltf-validator`) and prints one
// JSON line per file: {file, errors, warnings, infos, hints, messages: [{code, severity, pointer,
// message}]} (severity 0 error, 1 warning, 2 info, 3 hint). Exits 0 when it could validate every
// file (whatever it found), 2 on a usage or I/O error. The tests decide what counts as a failure.
//
// usage: node validate.mjs FILE.glb…
import { readFile } from 'node:fs/promises';
import path from 'node:path';
import validator from 'gltf-validator';

const files = process.argv.slice(2);
if (files.length === 0) {
  console.error('usage: node validate.mjs FILE.glb…');
  process.exit(2);
}
for (const file of files) {
  let bytes;
  try {
    bytes = new Uint8Array(await readFile(file));
  } catch (e) {
    console.error(`${file}: cannot read it: ${e.message}`);
    process.exit(2);
  }
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 0,
    // a .glb holds everything; nothing external is loaded
    externalResourceFunction: (uri) => Promise.reject(new Error(`external resource ${uri} not allowed`)),
  });
  const issues = report.issues;
  console.log(JSON.stringify({
    file,
    errors: issues.numErrors,
    warnings: issues.numWarnings,
    infos: issues.numInfos,
    hints: issues.numHints,
    messages: issues.messages.map((m) => ({
      code: m.code, severity: m.severity, pointer: m.pointer, message: m.message,
    })),
  }));
}
