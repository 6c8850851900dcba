// Validates .glb/.gltf files with the Khronos glTF-Validator (npm package `gltf-validator`) and
// prints, per file, "FILE: errors E warnings W infos I hints H" and every issue; exits 1 if any
// file has an error or a warning. Used by tests/export_gltf.rs when MATFIT_GLTF_VALIDATOR names
// this script (docs/USAGE.md, "export"); not part of CI, which has no node.
//
//   npm install --prefix /tmp/gv gltf-validator
//   NODE_PATH=/tmp/gv/node_modules node tools/gltf_validate.js out.glb
const fs = require('fs');
const validator = require('gltf-validator');

async function main(files) {
    let bad = false;
    for (const file of files) {
        const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
            maxIssues: 100,
        });
        const i = report.issues;
        console.log(`${file}: errors ${i.numErrors} warnings ${i.numWarnings} ` +
            `infos ${i.numInfos} hints ${i.numHints}`);
        for (const m of i.messages) {
            const sev = ['error', 'warning', 'info', 'hint'][m.severity];
            console.log(`  ${sev} ${m.code} ${m.pointer || ''}: ${m.message}`);
        }
        bad = bad || i.numErrors > 0 || i.numWarnings > 0;
    }
    process.exit(bad ? 1 : 0);
}

main(process.argv.slice(2)).catch((e) => {
    console.error(`validator failed: ${e}`);
    process.exit(2);
});
