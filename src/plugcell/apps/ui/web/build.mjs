// Bundle three.js and OrbitControls into ../static/vendor/three.bundle.js (one ES module),
// and copy three's licence beside it.  Deterministic: the same lock file gives the same bytes
// (tests/ui/test_ui_bundle.py rebuilds and compares).
import { build } from "esbuild";
import { copyFileSync, mkdirSync, readFileSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const out = process.argv[2] || join(here, "..", "static", "vendor");
const three = JSON.parse(readFileSync(join(here, "node_modules", "three", "package.json"), "utf8"));
mkdirSync(out, { recursive: true });
await build({
  entryPoints: [join(here, "src", "three-entry.js")],
  bundle: true,
  format: "esm",
  minify: true,
  target: "es2020",
  legalComments: "inline",
  banner: { js: `/* three.js ${three.version} (MIT, see three.LICENSE) and OrbitControls, bundled by esbuild for plugcell's UI */` },
  outfile: join(out, "three.bundle.js"),
  logLevel: "warning",
});
copyFileSync(join(here, "node_modules", "three", "LICENSE"), join(out, "three.LICENSE"));
