// socket.io-client 4 against drive_server: the modern JavaScript client the server must keep serving.
// usage: node drive_client.js URL PAYLOADS.json
// PAYLOADS.json is a JSON array of telemetry payloads (null = manual mode) sent closed loop, one per reply.
// Prints one JSON line per reply: {"event": "steer"|"manual", "data": {...}}, then {"done": true}.
const fs = require("fs");
const { io } = require("socket.io-client");

const [url, payloadsPath] = process.argv.slice(2);
const payloads = JSON.parse(fs.readFileSync(payloadsPath, "utf8"));
const socket = io(url, { transports: ["websocket"], reconnection: false, timeout: 10000 });
let next = 0;

function sendNext() {
  if (next >= payloads.length) {
    console.log(JSON.stringify({ done: true }));
    socket.close();
    return;
  }
  socket.emit("telemetry", payloads[next++]);
}

for (const event of ["steer", "manual"]) {
  socket.on(event, (data) => {
    console.log(JSON.stringify({ event, data }));
    sendNext();
  });
}
socket.on("connect", sendNext);
socket.on("connect_error", (err) => {
  console.error("connect_error: " + err.message);
  process.exit(3);
});
setTimeout(() => {
  console.error("timeout");
  process.exit(4);
}, 20000).unref();
