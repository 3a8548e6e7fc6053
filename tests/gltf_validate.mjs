#!/usr/bin/env node
// Validate a .glb/.gltf with the Khronos glTF-Validator and print its JSON report to stdout.
//
//   node tests/gltf_validate.mjs FILE
//
// The npm package `gltf-validator` is resolved from node_modules at the repository root:
//   npm install --no-save --prefix <repo root> gltf-validator
// Exit status: 0 when the report has no errors, 1 when it has errors, 2 when no report could be
// made (missing package, unreadable file, undetectable format).

import { readFile } from "node:fs/promises";
import { createRequire } from "node:module";
import path from "node:path";
import { fileURLToPath } from "node:url";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "..");
const require = createRequire(path.join(root, "package.json"));

function fail(message) {
  console.error(`gltf_validate: ${message}`);
  process.exit(2);
}

if (process.argv.length !== 3) fail("usage: node tests/gltf_validate.mjs FILE");
const file = path.resolve(process.argv[2]);

let validator;
try {
  validator = require("gltf-validator");
} catch {
  fail(`npm package gltf-validator not found under ${root}/node_modules ` +
       `(npm install --no-save --prefix ${root} gltf-validator)`);
}

let bytes;
try {
  bytes = new Uint8Array(await readFile(file));
} catch (err) {
  fail(`cannot read ${file}: ${err.message}`);
}

try {
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 0, // report every issue
    externalResourceFunction: (uri) =>
      readFile(path.resolve(path.dirname(file), decodeURIComponent(uri))).then(
        (data) => new Uint8Array(data),
      ),
  });
  process.stdout.write(JSON.stringify(report, null, 2) + "\n");
  process.exit(report.issues.numErrors > 0 ? 1 : 0);
} catch (err) {
  fail(`validation failed for ${file}: ${err}`);
}
