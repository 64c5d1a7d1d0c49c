// Validate a .gltf or .glb with the Khronos glTF validator (npm package gltf-validator, which
// scripts/install_deps.sh installs). Usage: node gltf_validate.js VALIDATOR_DIR FILE
// Prints the validator's report as JSON on stdout; exits 0 when it ran (the caller reads the
// issue counts), 2 when it could not run.
const fs = require("fs");
const path = require("path");

const [validatorDir, file] = process.argv.slice(2);
if (!validatorDir || !file) {
  console.error("usage: node gltf_validate.js VALIDATOR_DIR FILE");
  process.exit(2);
}
const validator = require(path.resolve(validatorDir));
const folder = path.dirname(path.resolve(file));

validator
  .validateBytes(new Uint8Array(fs.readFileSync(file)), {
    uri: path.basename(file),
    maxIssues: 100,
    // A .gltf's buffers and images beside it.
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.join(folder, decodeURIComponent(uri)), (err, data) =>
          err ? reject(err.toString()) : resolve(new Uint8Array(data)));
      }),
  })
  .then((report) => console.log(JSON.stringify(report)))
  .catch((err) => {
    console.error(`gltf-validator failed: ${err}`);
    process.exit(2);
  });
