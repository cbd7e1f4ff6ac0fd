// Open an IFC file with web-ifc (an IFC reader independent of IfcOpenShell) and print what it
// found as one line of JSON: counts of entities, the meshes of its plates and members, their
// total area, and every message web-ifc logged (tests/test_ifc.py).
const fs = require("fs");
const WebIFC = require(process.env.WEB_IFC_MODULE || "web-ifc");
(async () => {
  const errors = [];
  for (const name of ["error", "warn", "log"]) {
    console[name] = (...args) => { errors.push(args.join(" ")); };
  }
  const api = new WebIFC.IfcAPI();
  await api.Init();
  const model = api.OpenModel(new Uint8Array(fs.readFileSync(process.argv[2])));
  const count = (type) => api.GetLineIDsWithType(model, type).size();
  let area = 0, meshes = 0, triangles = 0;
  api.StreamAllMeshesWithTypes(model, [WebIFC.IFCPLATE, WebIFC.IFCMEMBER], (mesh) => {
    meshes += 1;
    for (let g = 0; g < mesh.geometries.size(); g++) {
      const placed = mesh.geometries.get(g);
      const geometry = api.GetGeometry(model, placed.geometryExpressID);
      const v = api.GetVertexArray(geometry.GetVertexData(), geometry.GetVertexDataSize());
      const ix = api.GetIndexArray(geometry.GetIndexData(), geometry.GetIndexDataSize());
      for (let t = 0; t < ix.length; t += 3) {
        const p = [ix[t], ix[t + 1], ix[t + 2]].map((i) => [v[6 * i], v[6 * i + 1], v[6 * i + 2]]);
        const a = [0, 1, 2].map((k) => p[1][k] - p[0][k]), b = [0, 1, 2].map((k) => p[2][k] - p[0][k]);
        const c = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
        area += 0.5 * Math.hypot(c[0], c[1], c[2]);
        triangles += 1;
      }
      geometry.delete();
    }
  });
  const out = {schema: api.GetModelSchema(model), plates: count(WebIFC.IFCPLATE),
               members: count(WebIFC.IFCMEMBER), groups: count(WebIFC.IFCGROUP),
               nodes: count(WebIFC.IFCSTRUCTURALPOINTCONNECTION), meshes, triangles, area, errors};
  api.CloseModel(model);
  process.stdout.write(JSON.stringify(out) + "\n");
})().catch((e) => { process.stdout.write(JSON.stringify({crash: String(e)}) + "\n"); process.exit(1); });
