// Run the Khronos glTF-Validator (npm package "gltf-validator") on glTF files; print JSON reports.
// usage: node gltf_validate.cjs NODE_MODULES_DIR FILE [MAX_ISSUES]   (one file: its report)
//        node gltf_validate.cjs NODE_MODULES_DIR --serve             (one JSON request a line on
//        stdin, {"file": ..., "maxIssues": ...}; one line out per request: {"report": ...} or
//        {"error": "..."}; exits at the end of stdin)
const path = require('path');
const fs = require('fs');
const readline = require('readline');
const validator = require(path.join(process.argv[2], 'gltf-validator'));

function validate(file, maxIssues) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  return validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: maxIssues,
    externalResourceFunction: (uri) => new Promise((resolve, reject) => {
      const p = path.resolve(path.dirname(file), decodeURIComponent(uri));
      fs.readFile(p, (err, data) => err ? reject(err.toString()) : resolve(new Uint8Array(data)));
    }),
  });
}

if (process.argv[3] === '--serve') {
  const lines = readline.createInterface({ input: process.stdin, terminal: false });
  let queue = Promise.resolve();
  lines.on('line', (line) => {
    queue = queue.then(async () => {
      let out;
      try {
        const req = JSON.parse(line);
        out = { report: await validate(req.file, req.maxIssues) };
      } catch (error) {
        out = { error: String(error) };
      }
      process.stdout.write(JSON.stringify(out) + '\n');
    });
  });
} else {
  const file = process.argv[3];
  const maxIssues = parseInt(process.argv[4] || '1000', 10);
  Promise.resolve().then(() => validate(file, maxIssues)).then((report) => {
    process.stdout.write(JSON.stringify(report));
  }).catch((error) => {
    process.stderr.write(String(error));
    process.exit(3);
  });
}
