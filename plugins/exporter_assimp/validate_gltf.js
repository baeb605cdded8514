// Validate a .gltf or .glb with the Khronos glTF validator (npm library, tools/node/package.json).
// Usage: node validate_gltf.js <node_modules folder> <file.gltf|file.glb>
// Prints every issue as "SEVERITY CODE pointer: message" and a summary line; exit code 0 when the
// report has no errors, 1 when it has errors, 2 when validation could not run.
'use strict';
const fs = require('fs');
const path = require('path');

const [modules, file] = process.argv.slice(2);
if (!modules || !file) {
  console.error('usage: node validate_gltf.js <node_modules folder> <file.gltf|file.glb>');
  process.exit(2);
}
let validator;
try {
  validator = require(path.join(path.resolve(modules), 'gltf-validator'));
} catch (e) {
  console.error(`cannot load gltf-validator from ${modules}: ${e.message}` +
                ' (install it: npm ci --prefix tools/node)');
  process.exit(2);
}

const severities = ['ERROR', 'WARNING', 'INFO', 'HINT'];
const full = path.resolve(file);
validator.validateBytes(new Uint8Array(fs.readFileSync(full)), {
  uri: path.basename(full),
  maxIssues: 0,  // no limit
  externalResourceFunction: (uri) => new Promise((resolve, reject) => {
    const resource = path.resolve(path.dirname(full), decodeURIComponent(uri));
    fs.readFile(resource, (err, data) => err ? reject(err.toString()) : resolve(new Uint8Array(data)));
  }),
}).then((report) => {
  for (const m of report.issues.messages) {
    console.log(`${severities[m.severity] || m.severity} ${m.code} ${m.pointer || ''}: ${m.message}`);
  }
  const i = report.issues;
  console.log(`summary: ${i.numErrors} errors, ${i.numWarnings} warnings, ${i.numInfos} infos, ` +
              `${i.numHints} hints (${report.validatorVersion}, ${file})`);
  process.exit(i.numErrors === 0 ? 0 : 1);
}, (error) => {
  console.error(`validation failed to run on ${file}: ${error}`);
  process.exit(2);
});
