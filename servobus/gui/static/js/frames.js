// Binary scope frames (servobus/gui/frames.py): 48-byte header, f64 x, f32 y per channel.

export const FLAG_TRIGGERED = 1, FLAG_HOLDING = 2, FLAG_PAIRS = 4, FLAG_FREE_RUN = 8;
const HEADER = 48;

export function parseFrame(buf) {
  const dv = new DataView(buf);
  const version = dv.getUint8(0), kind = dv.getUint8(1);
  if (version !== 1 || kind !== 1) throw new Error(`not a scope frame (${version}/${kind})`);
  const nch = dv.getUint8(2), flags = dv.getUint8(3), n = dv.getUint32(4, true);
  const frame = {
    flags, n,
    tRef: dv.getFloat64(8, true), rate: dv.getFloat64(16, true),
    seq: dv.getUint32(24, true), raw: dv.getUint32(28, true),
    newest: dv.getFloat64(32, true), sent: dv.getFloat64(40, true),
    x: new Float64Array(buf, HEADER, n), ys: [],
  };
  let at = HEADER + 8 * n;
  for (let i = 0; i < nch; i++) { frame.ys.push(new Float32Array(buf, at, n)); at += 4 * n; }
  return frame;
}
