// Bundles the observer page for the build (web/CMakeLists.txt runs it):
//   node bundle.mjs --src web/page --out <build>/share/neurosim-web --node-modules <npm dir>/node_modules
//                   --generated <build dir of the generated modules>
// src/main.js and everything it imports (three.js from node_modules; './generated/NAME.js' from
// the --generated folder, files the build writes from C++ headers) become one minified ES
// module, app.js; index.html and style.css are copied next to it. The licence comments of the
// bundled packages are kept at the end of app.js.
import { createRequire } from 'node:module';
import { copyFileSync, mkdirSync } from 'node:fs';
import { join, resolve } from 'node:path';

function arg(name) {
  const i = process.argv.indexOf(name);
  if (i < 0 || i + 1 >= process.argv.length) {
    console.error(`bundle.mjs: ${name} DIR is required`);
    process.exit(2);
  }
  return resolve(process.argv[i + 1]);
}

const src = arg('--src');
const out = arg('--out');
const nodeModules = arg('--node-modules');
const generated = arg('--generated');
const require = createRequire(join(nodeModules, 'noop.js'));
const esbuild = require('esbuild');

mkdirSync(out, { recursive: true });
await esbuild.build({
  entryPoints: [join(src, 'src', 'main.js')],
  outfile: join(out, 'app.js'),
  bundle: true,
  minify: true,
  format: 'esm',
  target: ['es2020'],
  nodePaths: [nodeModules],
  legalComments: 'eof',
  plugins: [{
    name: 'generated',
    setup(build) {
      build.onResolve({ filter: /^\.\/generated\/[a-z_]+\.js$/ }, (a) => ({
        path: join(generated, a.path.slice('./generated/'.length)),
      }));
    },
  }],
  logLevel: 'warning',
});
for (const f of ['index.html', 'style.css']) copyFileSync(join(src, f), join(out, f));
