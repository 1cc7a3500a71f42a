// Checks Kubernetes manifests against the API they target, two ways, both from the
// schemas of the Kubernetes 1.33 OpenAPI (kubernetes-models) and KEDA's CRDs
// (@kubernetes-models/keda, KEDA 2.10.1):
//  1. each document through the JSON-schema validator compiled from its kind's schema
//     (types, required fields, formats);
//  2. every document as a typed TypeScript object literal, compiled with `strict`: a field
//     the schema does not have is an error (what `kubectl apply` with strict field
//     validation, the default since Kubernetes 1.27, refuses).
// Usage: node check.mjs FILE.yaml...   Prints one line per document; exits 1 on any error.
import fs from "node:fs";
import path from "node:path";
import { fileURLToPath } from "node:url";
import yaml from "js-yaml";
import ts from "typescript";

const here = path.dirname(fileURLToPath(import.meta.url));

// The module that models `apiVersion`'s `kind`.
function modelModule(apiVersion, kind) {
  if (apiVersion.startsWith("keda.sh/")) {
    return `@kubernetes-models/keda/${apiVersion}/${kind}`;
  }
  return `kubernetes-models/${apiVersion}/${kind}`;
}

const docs = [];
for (const file of process.argv.slice(2)) {
  yaml.loadAll(fs.readFileSync(file, "utf8"), (doc) => {
    if (doc) docs.push({ file: path.basename(file), doc });
  });
}
if (docs.length === 0) {
  console.error("no manifests given");
  process.exit(1);
}

let failed = 0;
const imports = [];
const literals = [];
for (const [i, { file, doc }] of docs.entries()) {
  const what = `${file}: ${doc.kind} ${doc.metadata?.name ?? ""}`;
  const module = modelModule(String(doc.apiVersion), String(doc.kind));
  let model;
  try {
    model = (await import(module))[doc.kind];
  } catch {
    console.log(`FAIL ${what}: no schema for ${doc.apiVersion} ${doc.kind}`);
    failed++;
    continue;
  }
  try {
    new model(doc).validate();
    console.log(`ok   ${what} (${doc.apiVersion})`);
  } catch (e) {
    console.log(`FAIL ${what}: ${e.message}`);
    failed++;
  }
  imports.push(`import type { I${doc.kind} as T${i} } from "${module}";`);
  literals.push(`// ${what}\nexport const doc${i}: T${i} = ${JSON.stringify(doc, null, 1)};`);
}

// The typed literals, compiled in memory beside node_modules (for the imports).
const source = path.join(here, "manifests.generated.ts");
const text = `${imports.join("\n")}\n${literals.join("\n")}\n`;
const options = {
  strict: true,
  noEmit: true,
  skipLibCheck: true,
  target: ts.ScriptTarget.ES2020,
  module: ts.ModuleKind.ESNext,
  moduleResolution: ts.ModuleResolutionKind.Node10,
};
const host = ts.createCompilerHost(options);
const readFile = host.readFile.bind(host);
const fileExists = host.fileExists.bind(host);
const getSourceFile = host.getSourceFile.bind(host);
host.readFile = (f) => (f === source ? text : readFile(f));
host.fileExists = (f) => f === source || fileExists(f);
host.getSourceFile = (f, v, ...rest) =>
  f === source ? ts.createSourceFile(f, text, v) : getSourceFile(f, v, ...rest);
const program = ts.createProgram([source], options, host);
for (const d of ts.getPreEmitDiagnostics(program)) {
  let where = "";
  if (d.file && d.start !== undefined) {
    // The document the error is in: the nearest `// file: kind name` line above it.
    const before = d.file.text.slice(0, d.start);
    where = before.slice(before.lastIndexOf("\n// ") + 4).split("\n")[0] + ": ";
  }
  console.log(`FAIL ${where}${ts.flattenDiagnosticMessageText(d.messageText, " ")}`);
  failed++;
}
if (failed > 0) {
  console.log(`${failed} errors in ${docs.length} documents`);
  process.exit(1);
}
console.log(`${docs.length} documents match the Kubernetes 1.33 and KEDA 2.10 schemas`);
