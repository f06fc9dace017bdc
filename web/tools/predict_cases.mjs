// Runs the web viewer's prediction rule (../viewer/predict.js) over cases read as JSON from
// standard input, {grid, rule, cases: [{position, velocity}]}, and prints the predicted cell ids
// per case as one JSON array of arrays. The test `the_viewer_predicts_as_the_runtime` compares
// them with lemi-runtime's `predict`.
import { predict } from '../viewer/predict.js';

let input = '';
for await (const chunk of process.stdin) input += chunk;
const { grid, rule, cases } = JSON.parse(input);
console.log(JSON.stringify(cases.map((c) => predict(c.position, c.velocity, grid, rule).map((p) => p.id))));
