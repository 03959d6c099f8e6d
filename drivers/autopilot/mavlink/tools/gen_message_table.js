// Prints the rows of src/message_table.cpp: the MAVLink message table (id, CRC_EXTRA, base length, length with extensions) of the
// minimal, common and ardupilotmega dialects from mavlink-mappings (generated from the XML).
// Usage: npm pack mavlink-mappings && tar xzf mavlink-mappings-*.tgz && node gen_message_table.js ./package/dist/index.js
const m = require(process.argv[2] || 'mavlink-mappings');
const reg = { ...m.minimal.REGISTRY, ...m.common.REGISTRY, ...m.ardupilotmega.REGISTRY };
const rows = [];
for (const id of Object.keys(reg).map(Number).sort((a, b) => a - b)) {
  const c = reg[id];
  let base = 0, full = 0;
  for (const f of c.FIELDS) {
    const end = f.offset + f.size * (f.length || 1);
    full = Math.max(full, end);
    if (!f.extension) base = Math.max(base, end);
  }
  if (full !== c.PAYLOAD_LENGTH) throw new Error(`${c.MSG_NAME}: ${full} != ${c.PAYLOAD_LENGTH}`);
  rows.push(`    {${id}, ${c.MAGIC_NUMBER}, ${base}, ${full}},  // ${c.MSG_NAME}`);
}
console.log(rows.join('\n'));
