// Reads an MCAP file with the official readers and prints what it holds as JSON, for our tests:
//   node read_mcap.mjs FILE [--dump TOPIC]... [--max N] [--expect recording.json]
// McapIndexedReader (summary, chunk indexes, every message through the indexes, chunk CRCs) and
// McapStreamReader (every record in file order, CRCs validated); the data section CRC is checked with
// @foxglove/crc. Each JSON message is parsed and its keys compared with its channel's JSON schema.
// "schemaless" lists the channels without a schema. --expect compares the per-topic counts
// with what the writer reported (recording.json's channel_messages): every mismatch is a problem.
// Exit 0 and {"ok":true,...} when the file reads; 1 and {"ok":false,"error":...,"damage":"truncated" or
// "corrupted"} when it does not (no closing magic: truncated; otherwise a CRC, a record or a
// decompression failed: corrupted); 2 on bad arguments.
import fs from 'node:fs';
import { McapIndexedReader, McapStreamReader } from '@mcap/core';
import { loadDecompressHandlers } from '@mcap/support';
import { crc32 } from '@foxglove/crc';

const args = process.argv.slice(2);
if (args.includes('--help')) {
  console.log('usage: node read_mcap.mjs FILE [--dump TOPIC]... [--max N] [--expect recording.json]   (prints JSON: header, schemas, channels, statistics, counts, chunks)');
  process.exit(0);
}
let file;
const dump = new Set();
let max = 3;
let expect;
for (let i = 0; i < args.length; i++) {
  if (args[i] === '--dump' || args[i] === '--max' || args[i] === '--expect') {
    if (i + 1 >= args.length) { console.error(`read_mcap: ${args[i]} needs a value`); process.exit(2); }
    if (args[i] === '--dump') dump.add(args[++i]); else if (args[i] === '--max') max = Number(args[++i]); else expect = args[++i];
  } else if (args[i].startsWith('--')) { console.error(`read_mcap: unknown option ${args[i]}`); process.exit(2); }
  else if (file === undefined) file = args[i];
  else { console.error(`read_mcap: one file only (got ${file} and ${args[i]})`); process.exit(2); }
}
if (file === undefined) { console.error('read_mcap: no file given (usage: node read_mcap.mjs FILE)'); process.exit(2); }

const text = new TextDecoder();
const big = (v) => Number(v);

async function main() {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const decompressHandlers = await loadDecompressHandlers();
  const readable = { size: async () => BigInt(bytes.length), read: async (off, len) => bytes.subarray(Number(off), Number(off + len)) };
  const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  const out = { ok: true, size: bytes.length, header: { profile: reader.header.profile, library: reader.header.library } };
  out.schemas = [...reader.schemasById.values()].map((s) => ({ id: s.id, name: s.name, encoding: s.encoding, data: text.decode(s.data) }));
  out.channels = [...reader.channelsById.values()].map((c) => ({
    id: c.id, topic: c.topic, message_encoding: c.messageEncoding, schema_id: c.schemaId,
    schema_name: reader.schemasById.get(c.schemaId)?.name ?? '', metadata: Object.fromEntries(c.metadata),
  }));
  const st = reader.statistics;
  out.statistics = st && {
    message_count: big(st.messageCount), schema_count: st.schemaCount, channel_count: st.channelCount, chunk_count: st.chunkCount,
    metadata_count: st.metadataCount, message_start_time: big(st.messageStartTime), message_end_time: big(st.messageEndTime),
    channel_message_counts: Object.fromEntries([...st.channelMessageCounts].map(([id, n]) => [reader.channelsById.get(id)?.topic ?? String(id), big(n)])),
  };
  out.chunk_indexes = reader.chunkIndexes.length;
  out.chunks = reader.chunkIndexes.map((c) => ({ offset: big(c.chunkStartOffset), length: big(c.chunkLength), compression: c.compression,
    compressed_size: big(c.compressedSize), uncompressed_size: big(c.uncompressedSize) }));
  out.chunk_compression = [...new Set(reader.chunkIndexes.map((c) => c.compression))];
  out.summary_offsets = [...reader.summaryOffsetsByOpcode.keys()].sort((a, b) => a - b);
  out.metadata = [];
  for await (const m of reader.readMetadata()) out.metadata.push({ name: m.name, values: Object.fromEntries(m.metadata) });

  // Every message through the indexes: counts, sequences, time order, JSON against the schema.
  const schemaProps = new Map();
  for (const c of reader.channelsById.values()) {
    const s = reader.schemasById.get(c.schemaId);
    if (s && s.encoding === 'jsonschema') schemaProps.set(c.id, Object.keys(JSON.parse(text.decode(s.data)).properties ?? {}).sort());
  }
  const counts = {}, dumps = {}, lastSeq = new Map(), problems = [];
  let lastTime = -1n;
  for await (const m of reader.readMessages({ validateCrcs: true })) {
    const topic = reader.channelsById.get(m.channelId).topic;
    counts[topic] = (counts[topic] ?? 0) + 1;
    if (m.logTime < lastTime) problems.push(`${topic}: log time ${m.logTime} before ${lastTime}`);
    lastTime = m.logTime;
    const prev = lastSeq.get(m.channelId) ?? 0;
    if (m.sequence !== prev + 1 && problems.length < 20) problems.push(`${topic}: sequence ${m.sequence} after ${prev}`);
    lastSeq.set(m.channelId, m.sequence);
    if (reader.channelsById.get(m.channelId).messageEncoding === 'json') {
      let v;
      try { v = JSON.parse(text.decode(m.data)); } catch (e) { problems.push(`${topic}: message ${m.sequence} is not JSON: ${e.message}`); continue; }
      const props = schemaProps.get(m.channelId);
      if (props) {
        const keys = Object.keys(v).sort();
        if (JSON.stringify(keys) !== JSON.stringify(props) && problems.length < 20)
          problems.push(`${topic}: message keys ${keys.join(',')} are not the schema's ${props.join(',')}`);
      }
      if (dump.has(topic)) {
        dumps[topic] ??= [];
        if (dumps[topic].length < max) dumps[topic].push({ log_time: big(m.logTime), publish_time: big(m.publishTime), sequence: m.sequence, data: v });
      }
    }
  }
  out.schemaless = [...reader.channelsById.values()].filter((c) => c.schemaId === 0).map((c) => c.topic);
  if (expect !== undefined) {
    const want = JSON.parse(fs.readFileSync(expect, 'utf8')).channel_messages ?? {};
    for (const t of new Set([...Object.keys(want), ...Object.keys(counts)]))
      if ((want[t] ?? 0) !== (counts[t] ?? 0)) problems.push(`${t}: ${counts[t] ?? 0} messages read, ${want[t] ?? 0} reported by ${expect}`);
  }
  out.counts = counts;
  out.dumps = dumps;
  out.problems = problems;

  // Every record in file order through the stream reader, CRCs validated.
  const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true, includeChunks: true });
  stream.append(bytes);
  const records = {}, streamCounts = {};
  const streamChannels = new Map();
  let dataEnd;
  for (let r; (r = stream.nextRecord()); ) {
    records[r.type] = (records[r.type] ?? 0) + 1;
    if (r.type === 'Channel') streamChannels.set(r.id, r.topic);
    if (r.type === 'Message') { const t = streamChannels.get(r.channelId); streamCounts[t] = (streamCounts[t] ?? 0) + 1; }
    if (r.type === 'DataEnd') dataEnd = r;
  }
  if (!stream.done()) throw new Error(`stream reader: file ends inside a record (${stream.bytesRemaining()} bytes left over)`);
  out.records = records;
  out.stream_counts = streamCounts;
  const crc = crc32(bytes.subarray(0, Number(reader.dataEndOffset)));
  out.data_section_crc_ok = dataEnd !== undefined && dataEnd.dataSectionCrc === crc;
  if (!out.data_section_crc_ok) throw new Error(`data section CRC ${dataEnd?.dataSectionCrc} != computed ${crc}`);
  return out;
}

// process.exit() right after a large write to a pipe would cut it short: exit once it is flushed.
const emit = (obj, code) => process.stdout.write(JSON.stringify(obj) + '\n', () => process.exit(code));
// A file that does not end with the closing magic was cut short; one that does but fails was damaged.
const MAGIC = [0x89, 0x4d, 0x43, 0x41, 0x50, 0x30, 0x0d, 0x0a];
function damage() {
  try {
    const b = fs.readFileSync(file);
    return b.length >= 8 && MAGIC.every((v, k) => b[b.length - 8 + k] === v) ? 'corrupted' : 'truncated';
  } catch { return 'unreadable'; }
}
main().then((out) => emit(out, 0)).catch((e) => emit({ ok: false, error: String(e && e.message ? e.message : e), damage: damage() }, 1));
