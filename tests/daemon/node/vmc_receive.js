// A VMC marionette (receiver) made with osc.js (the npm `osc` package), an OSC implementation
// bodyd's authors did not write: receives bodyd's `--output vmc:` bundles and writes each as one
// JSON line, so a test can check them (tests/daemon/vmc_output_test.cpp).
//
//   node vmc_receive.js PORT_FILE OUT_FILE
//
// Binds UDP 127.0.0.1 on a free port, writes that port to PORT_FILE once listening, then appends
// one line per received bundle to OUT_FILE:
//   {"time_tag": {"raw": [sec, frac]}, "packets": [{"address": "/VMC/Ext/OK", "args": [{"type": "i", "value": 1}]}, ...]}
// Messages that arrive outside a bundle are written as {"message": {...}}. Runs until SIGTERM.
'use strict';
const fs = require('fs');
const osc = require('osc');

const [portFile, outFile] = process.argv.slice(2);
const out = fs.openSync(outFile, 'w');

const udp = new osc.UDPPort({localAddress: '127.0.0.1', localPort: 0, metadata: true});

udp.on('ready', () => {
  fs.writeFileSync(portFile + '.tmp', String(udp.socket.address().port));
  fs.renameSync(portFile + '.tmp', portFile);  // the reader never sees a half-written file
});

// osc.js emits "osc" once per datagram, with the whole packet (a bundle or a message).
udp.on('osc', (packet) => {
  const line = packet.packets !== undefined ?
    {time_tag: {raw: packet.timeTag.raw}, packets: packet.packets} :
    {message: packet};
  fs.writeSync(out, JSON.stringify(line) + '\n');
});

udp.on('error', (e) => {
  fs.writeSync(out, JSON.stringify({error: String(e && e.message ? e.message : e)}) + '\n');
});

process.on('SIGTERM', () => {
  fs.closeSync(out);
  udp.close();
  process.exit(0);
});

udp.open();
