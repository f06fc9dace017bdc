// Measures what Draco (KHR_draco_mesh_compression) would make of an exported cell: reads a
// `lemi export --geometry plain` .glb, compresses its meshes with Google's encoder through
// glTF-Transform at the given position and texture-coordinate bits, writes the result and prints
// its bytes, the images' bytes and the rest (docs/EXPORT.md, "Draco instead of meshoptimizer").
// Not part of the tests; its packages are not among the viewer's:
//   npm install --no-save @gltf-transform/core @gltf-transform/extensions draco3dgltf
//   node tools/measure-draco.mjs IN.glb OUT.glb POSITION_BITS TEXCOORD_BITS [sequential]
import fs from 'node:fs';
import { NodeIO } from '@gltf-transform/core';
import { KHRDracoMeshCompression, KHRONOS_EXTENSIONS } from '@gltf-transform/extensions';
import draco3d from 'draco3dgltf';

const [input, output, positionBits, texcoordBits, method] = process.argv.slice(2);
if (!input || !output || !(+positionBits > 0) || !(+texcoordBits > 0)) {
  console.error('usage: node tools/measure-draco.mjs IN.glb OUT.glb POSITION_BITS TEXCOORD_BITS [sequential]');
  process.exit(2);
}
const io = new NodeIO().registerExtensions(KHRONOS_EXTENSIONS).registerDependencies({
  'draco3d.encoder': await draco3d.createEncoderModule(),
  'draco3d.decoder': await draco3d.createDecoderModule(),
});
const doc = await io.read(input);
doc.createExtension(KHRDracoMeshCompression).setRequired(true).setEncoderOptions({
  method: method === 'sequential'
    ? KHRDracoMeshCompression.EncoderMethod.SEQUENTIAL
    : KHRDracoMeshCompression.EncoderMethod.EDGEBREAKER,
  encodeSpeed: 0,
  decodeSpeed: 0,
  quantizationBits: { POSITION: +positionBits, TEXCOORD: +texcoordBits },
  quantizationVolume: 'mesh',
});
await io.write(output, doc);
const bytes = fs.statSync(output).size;
let images = 0;
for (const t of (await io.read(output)).getRoot().listTextures()) images += t.getImage().byteLength;
console.log(`${output}: ${bytes} bytes, images ${images}, the rest ${bytes - images}`);
