// Connects to a live Foxglove WebSocket server with Foxglove's own client (@foxglove/ws-protocol's
// FoxgloveClient over ws) and prints what it saw as JSON, for our tests:
//   node check_live.mjs ws://HOST:PORT [--min-channels N] [--timeout S]
// 1. serverInfo and the advertised channels (waits for at least N); 2. subscribes to every channel
// (also ones advertised later) and waits until each has delivered a message; 3. unsubscribes all and
// counts what still arrives; 4. sends malformed messages one at a time and records the status reply to
// each; 5. subscribes again to show the server still serves. Exit 0 with {"ok":true,...} when the
// connection held through all steps (the test judges the content); 1 with {"ok":false,"error":...}.
import WebSocket from 'ws';
import wsProtocol from '@foxglove/ws-protocol';  // a CommonJS package: its default export holds the names
const { FoxgloveClient } = wsProtocol;

const args = process.argv.slice(2);
if (args.length === 0 || args.includes('--help')) {
  console.log('usage: node check_live.mjs ws://HOST:PORT [--min-channels N] [--timeout S]   (prints JSON)');
  process.exit(args.length === 0 ? 2 : 0);
}
const url = args[0];
let minChannels = 1;
let timeoutS = 8;
for (let i = 1; i < args.length; i++) {
  if (args[i] === '--min-channels') minChannels = Number(args[++i]);
  else if (args[i] === '--timeout') timeoutS = Number(args[++i]);
  else { console.error(`check_live: unknown argument ${args[i]}`); process.exit(2); }
}

const out = { ok: false, url, protocol: '', server_info: null, channels: [], topics: {}, after_unsubscribe: {}, refusals: [], resubscribed: null, errors: [] };
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
async function until(pred, seconds) {
  const end = Date.now() + seconds * 1000;
  while (!pred()) {
    if (Date.now() > end) return false;
    await sleep(20);
  }
  return true;
}
function finish(ok, error) {
  out.ok = ok;
  if (error) out.error = error;
  console.log(JSON.stringify(out));
  process.exit(ok ? 0 : 1);
}
setTimeout(() => finish(false, 'overall timeout'), (timeoutS * 3 + 10) * 1000).unref();

const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map();     // id -> channel
const subs = new Map();         // subscription id -> channel
const statuses = [];
let mode = 'collect';           // messages counted into out.topics ('collect'), out.after_unsubscribe ('after') or not ('ignore')
let closed = false;
const decoder = new TextDecoder();

client.on('open', () => { out.protocol = ws.protocol; });
client.on('error', (e) => out.errors.push(String(e?.message ?? e)));
client.on('close', () => { closed = true; });
client.on('serverInfo', (info) => { out.server_info = info; });
client.on('status', (s) => statuses.push(s));
client.on('advertise', (list) => {
  for (const c of list) {
    channels.set(c.id, c);
    out.channels.push({ id: c.id, topic: c.topic, encoding: c.encoding, schemaName: c.schemaName, schemaEncoding: c.schemaEncoding,
      schema_parses: (() => { try { JSON.parse(c.schema); return true; } catch { return false; } })() });
    if (subscribing) subscribe(c);
  }
});
client.on('message', ({ subscriptionId, timestamp, data }) => {
  const ch = subs.get(subscriptionId);
  const topic = ch ? ch.topic : `?sub${subscriptionId}`;
  const text = decoder.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength));
  if (mode === 'ignore') return;
  const into = mode === 'collect' ? out.topics : out.after_unsubscribe;
  const t = (into[topic] ??= { count: 0, bytes: 0, json_ok: true, keys: [], timestamp_ns: '0', unknown_subscription: !ch });
  t.count++;
  t.bytes += data.byteLength;
  t.timestamp_ns = String(timestamp);
  try {
    const j = JSON.parse(text);
    if (t.count === 1) {
      t.keys = Object.keys(j);
      if (Array.isArray(j.entities)) t.entity_ids = j.entities.map((e) => e.id);
      if (Array.isArray(j.transforms)) t.child_frames = j.transforms.map((x) => x.child_frame_id);
      if (j.position !== undefined || j.pose !== undefined) t.frame_id = j.frame_id;
      if (j.foxglove !== undefined) t.sample = j;
    }
    if (j.foxglove !== undefined) t.last = j;
    if (typeof j.data === 'string') t.data_bytes = Buffer.from(j.data, 'base64').length;
  } catch {
    t.json_ok = false;
  }
});

let subscribing = false;
function subscribe(c) {
  const id = client.subscribe(c.id);
  subs.set(id, c);
}

async function refusal(name, send) {
  const before = statuses.length;
  send();
  const got = await until(() => statuses.length > before || closed, 3);
  const s = got && statuses.length > before ? statuses[before] : null;
  out.refusals.push({ name, level: s ? s.level : null, message: s ? s.message : null, statuses: statuses.length - before });
}

async function main() {
  if (!(await until(() => out.server_info !== null && channels.size >= minChannels, timeoutS)))
    return finish(false, `no serverInfo or fewer than ${minChannels} channels in ${timeoutS} s (got ${channels.size}, closed=${closed})`);
  // 2. every channel, and the ones advertised later
  subscribing = true;
  for (const c of channels.values()) subscribe(c);
  await until(() => [...channels.values()].every((c) => (out.topics[c.topic]?.count ?? 0) > 0), timeoutS);
  // 3. unsubscribe all; what is already on the wire may still arrive (200 ms), then nothing may
  subscribing = false;
  for (const id of subs.keys()) client.unsubscribe(id);
  await sleep(200);
  mode = 'after';
  await sleep(1500);
  mode = 'ignore';
  // 4. malformed messages, one at a time
  const tf = [...channels.values()].find((c) => c.topic === '/tf');
  await refusal('not_json', () => ws.send('this is not json {'));
  await refusal('not_object', () => ws.send('[1,2,3]'));
  await refusal('unknown_op', () => ws.send(JSON.stringify({ op: 'fly', to: 'moon' })));
  await refusal('needs_capability', () => ws.send(JSON.stringify({ op: 'getParameters', parameterNames: [] })));
  await refusal('unknown_channel', () => ws.send(JSON.stringify({ op: 'subscribe', subscriptions: [{ id: 900, channelId: 99999 }] })));
  await refusal('bad_subscription_entry', () => ws.send(JSON.stringify({ op: 'subscribe', subscriptions: [{ id: -1, channelId: 'x' }] })));
  ws.send(JSON.stringify({ op: 'subscribe', subscriptions: [{ id: 901, channelId: tf ? tf.id : 1 }] }));
  await refusal('subscription_id_in_use', () => ws.send(JSON.stringify({ op: 'subscribe', subscriptions: [{ id: 901, channelId: tf ? tf.id : 1 }] })));
  await refusal('unknown_unsubscribe', () => ws.send(JSON.stringify({ op: 'unsubscribe', subscriptionIds: [12345] })));
  await refusal('binary_garbage', () => ws.send(Buffer.from([0xde, 0xad, 0xbe, 0xef, 0x00, 0x01, 0x02])));
  ws.send(JSON.stringify({ op: 'unsubscribe', subscriptionIds: [901] }));
  // 5. still served: a new subscription to the counters delivers (they carry the refusals counted)
  const counters = [...channels.values()].find((c) => c.topic === '/base/counters');
  if (counters) {
    mode = 'collect';
    delete out.topics[counters.topic];
    subscribe(counters);
    await until(() => (out.topics[counters.topic]?.count ?? 0) > 0 || closed, 3);
    out.resubscribed = out.topics[counters.topic] ?? null;
  }
  out.closed = closed;
  client.close();
  finish(!closed);
}
main().catch((e) => finish(false, String(e?.stack ?? e)));
