// Run the Khronos glTF-Validator (npm package "gltf-validator") on one file; print its JSON report.
// usage: node gltf_validate.cjs NODE_MODULES_DIR FILE [MAX_ISSUES]
const path = require('path');
const fs = require('fs');
const validator = require(path.join(process.argv[2], 'gltf-validator'));
const file = process.argv[3];
const maxIssues = parseInt(process.argv[4] || '1000', 10);
const bytes = new Uint8Array(fs.readFileSync(file));
validator.validateBytes(bytes, {
  uri: path.basename(file),
  maxIssues: maxIssues,
  externalResourceFunction: (uri) => new Promise((resolve, reject) => {
    const p = path.resolve(path.dirname(file), decodeURIComponent(uri));
    fs.readFile(p, (err, data) => err ? reject(err.toString()) : resolve(new Uint8Array(data)));
  }),
}).then((report) => {
  process.stdout.write(JSON.stringify(report));
}).catch((error) => {
  process.stderr.write(String(error));
  process.exit(3);
});
