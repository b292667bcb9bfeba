// Validate GLB files with the Khronos glTF-Validator; prints one JSON report per file.
// Usage: node validate-gltf.mjs FILE.glb [...]
import fs from 'node:fs';
import validator from 'gltf-validator';

const reports = [];
for (const path of process.argv.slice(2)) {
  const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(path)), {
    maxIssues: 50,
  });
  reports.push({ path, validatorVersion: report.validatorVersion, issues: report.issues });
}
console.log(JSON.stringify(reports));
