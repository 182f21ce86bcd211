// Writes tests/sensors/data/official_writer_ros2.mcap with the official MCAP writer (npm
// @mcap/core, MIT; not a dependency of evio, only how the fixture was made): a ROS 2 style MCAP
// (profile ros2, zstd chunks through the zstd CLI, summary, a rosbag2 Metadata record) holding
// dvs_msgs/msg/EventArray and sensor_msgs/msg/Imu messages in little-endian CDR, encoded here
// independently of evio's test writer. test_rosbag2.cc recomputes the same values.
//   npm install @mcap/core && node make_official_writer_ros2.js official_writer_ros2.mcap
const fs = require("fs");
const { execFileSync } = require("child_process");
const { McapWriter } = require("@mcap/core");
class Sink { constructor() { this.parts = []; this.pos = 0n; } async write(b) { this.parts.push(Buffer.from(b)); this.pos += BigInt(b.length); } position() { return this.pos; } }
class Cdr {
  constructor() { this.b = [0, 1, 0, 0]; }
  align(n) { while ((this.b.length - 4) % n) this.b.push(0); }
  u8(v) { this.b.push(v & 255); }
  u16(v) { this.align(2); this.b.push(v & 255, (v >> 8) & 255); }
  u32(v) { this.align(4); for (let i = 0; i < 4; i++) this.b.push(Number((BigInt(v) >> BigInt(8 * i)) & 255n)); }
  f64(v) { this.align(8); const d = Buffer.alloc(8); d.writeDoubleLE(v); for (const x of d) this.b.push(x); }
  str(s) { this.u32(s.length + 1); for (const c of Buffer.from(s)) this.b.push(c); this.b.push(0); }
  header(t) { this.u32(Number(t / 1000000000n)); this.u32(Number(t % 1000000000n)); this.str("cam0"); }
  bytes() { return new Uint8Array(this.b); }
}
(async () => {
  const sink = new Sink();
  const w = new McapWriter({ writable: sink, chunkSize: 2048,
    compressChunk: (d) => ({ compression: "zstd", compressedData: execFileSync("zstd", ["-c", "-q"], { input: d }) }) });
  await w.start({ profile: "ros2", library: "mcap-js official writer" });
  const se = await w.registerSchema({ name: "dvs_msgs/msg/EventArray", encoding: "ros2msg", data: new TextEncoder().encode("std_msgs/Header header\nuint32 height\nuint32 width\nEvent[] events") });
  const si = await w.registerSchema({ name: "sensor_msgs/msg/Imu", encoding: "ros2msg", data: new TextEncoder().encode("std_msgs/Header header") });
  const qos = new Map([["offered_qos_profiles", "- history: 3\n  depth: 0\n"]]);
  const ce = await w.registerChannel({ schemaId: se, topic: "/dvs/events", messageEncoding: "cdr", metadata: qos });
  const ci = await w.registerChannel({ schemaId: si, topic: "/dvs/imu", messageEncoding: "cdr", metadata: qos });
  await w.addMetadata({ name: "rosbag2", metadata: new Map([["serialized_metadata", "rosbag2_bagfile_information: {}"]]) });
  const t0 = 1700000000000000000n;
  // Event k (0..499): t = t0 + 1000 k + 7 (k % 3) ns, x = (37 k) % 346, y = (11 k) % 260, ON when k % 3 == 0.
  for (let m = 0; m < 5; m++) {
    const c = new Cdr();
    c.header(t0 + BigInt(100000 * m));
    c.u32(260); c.u32(346); c.u32(100);
    for (let i = 0; i < 100; i++) {
      const k = 100 * m + i, t = t0 + BigInt(1000 * k + 7 * (k % 3));
      c.u16((37 * k) % 346); c.u16((11 * k) % 260);
      c.u32(Number(t / 1000000000n)); c.u32(Number(t % 1000000000n)); c.u8(k % 3 === 0 ? 1 : 0);
    }
    const tl = t0 + BigInt(100000 * m + 99999);
    await w.addMessage({ channelId: ce, sequence: m, logTime: tl, publishTime: tl, data: c.bytes() });
    // IMU j = m: t = t0 + 100 us m + 50 us; gyro (0.01 m, -0.02, 0.03), accel (0.1, 9.81, -0.5 m).
    const ti = t0 + BigInt(100000 * m + 50000);
    const d = new Cdr();
    d.header(ti);
    for (const v of [0, 0, 0, 1]) d.f64(v);
    for (let i = 0; i < 9; i++) d.f64(0);
    for (const v of [0.01 * m, -0.02, 0.03]) d.f64(v);
    for (let i = 0; i < 9; i++) d.f64(0);
    for (const v of [0.1, 9.81, -0.5 * m]) d.f64(v);
    for (let i = 0; i < 9; i++) d.f64(0);
    await w.addMessage({ channelId: ci, sequence: m, logTime: ti, publishTime: ti, data: d.bytes() });
  }
  await w.end();
  fs.writeFileSync(process.argv[2], Buffer.concat(sink.parts));
})();
