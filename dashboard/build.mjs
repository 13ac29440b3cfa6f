// Bundles the dashboard into the Python package's folder (argument 1, default ../service/dashboard):
// index.html, app.js (three.js and the page's modules, minified), app.css, and build.json last.
// Run by the Python build (build_backend/hairport_build.py), or by hand: `npm run build`.
import { build } from "esbuild";
import { copyFileSync, mkdirSync, readFileSync, rmSync, writeFileSync } from "node:fs";
import { dirname, join, resolve } from "node:path";
import { fileURLToPath } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const output = resolve(process.argv[2] ?? join(here, "..", "service", "dashboard"));
rmSync(output, { recursive: true, force: true });
mkdirSync(output, { recursive: true });

const result = await build({
  entryPoints: { app: join(here, "src", "main.js"), style: join(here, "src", "style.css") },
  bundle: true,
  minify: true,
  sourcemap: false,
  format: "esm",
  target: ["es2022"],
  outdir: output,
  metafile: true,
  logLevel: "warning",
});
if (result.warnings.length) {
  console.error(`the dashboard's bundle has ${result.warnings.length} warning(s) (above): fix them`);
  process.exit(1);
}
copyFileSync(join(here, "src", "index.html"), join(output, "index.html"));
const three = JSON.parse(readFileSync(join(here, "node_modules", "three", "package.json"), "utf8")).version;
const bytes = Object.fromEntries(Object.entries(result.metafile.outputs).map(([file, info]) => [file.split("/").pop(), info.bytes]));
writeFileSync(join(output, "build.json"), JSON.stringify({ three, bytes }, null, 1) + "\n");
console.log(`dashboard bundled into ${output}: ${JSON.stringify(bytes)}`);
