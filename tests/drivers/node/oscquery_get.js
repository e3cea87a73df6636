// Asks bodyd's OSCQuery HTTP endpoint what VRChat would ask, with Node's http module, and
// prints what came back as one JSON object: {PATH: {"status", "content_type", "json" | "text"}}.
//
//   node oscquery_get.js PORT
'use strict';
const http = require('http');

const port = Number(process.argv[2]);
const paths = ['/', '/?HOST_INFO', '/tracking/vrsystem', '/tracking/vrsystem/head/pose',
               '/tracking/vrsystem/leftwrist/pose?TYPE', '/tracking/vrsystem?TYPE', '/tracking/nothing',
               '/?NOT_AN_ATTRIBUTE'];

function get(path) {
  return new Promise((resolve) => {
    const req = http.get({host: '127.0.0.1', port, path, timeout: 3000}, (res) => {
      let body = '';
      res.setEncoding('utf8');
      res.on('data', (chunk) => (body += chunk));
      res.on('end', () => {
        const out = {status: res.statusCode, content_type: res.headers['content-type'] || ''};
        try {
          out.json = JSON.parse(body);
        } catch (e) {
          out.text = body;
        }
        resolve(out);
      });
    });
    req.on('timeout', () => req.destroy(new Error('timeout')));
    req.on('error', (e) => resolve({status: 0, error: e.message}));
  });
}

(async () => {
  const result = {};
  for (const p of paths) result[p] = await get(p);
  console.log(JSON.stringify(result));
})();
