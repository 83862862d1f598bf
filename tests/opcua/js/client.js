// An independent OPC UA client (node-opcua) that pytest runs against `plugcell opcua serve`.
//
//   node client.js SCENARIO ENDPOINT CELL [OPTIONS-JSON]
//
// prints one JSON object (what it saw) on stdout and exits 0; any unexpected error
// exits 1 with the error on stderr; the whole run is bounded (OPTIONS.limitMs).
// OPTIONS: {user, password, certificate, privateKey, applicationUri, trustCa, secure,
//           limitMs}.
"use strict";

const {
  OPCUAClient, MessageSecurityMode, SecurityPolicy, AttributeIds, DataType,
  ClientSubscription, ClientMonitoredItem, TimestampsToReturn, UserTokenType,
  constructEventFilter, StatusCodes, OPCUACertificateManager,
} = require("node-opcua");
const os = require("os");
const path = require("path");
const fs = require("fs");

const [scenario, endpoint, cell, optionsText] = process.argv.slice(2);
const options = JSON.parse(optionsText || "{}");
const limit = setTimeout(() => {
  process.stderr.write(`client.js ${scenario}: no result within ${options.limitMs || 30000} ms\n`);
  process.exit(3);
}, options.limitMs || 30000);

function variant(dataType, value) { return { dataType, value }; }
const str = (s) => variant(DataType.String, s);
const int32 = (v) => variant(DataType.Int32, v);
const double = (v) => variant(DataType.Double, v);

function statusName(code) { return code.name; }

async function open(options) {
  // one PKI folder for every run (node-opcua makes its client certificate once, ~3 s)
  const pki = path.join(os.tmpdir(), `plugcell-opcua-test-pki-${os.userInfo().uid}`);
  const clientCertificateManager = new OPCUACertificateManager({
    rootFolder: pki, automaticallyAcceptUnknownCertificate: true,
  });
  if (options.trustCa) {  // the cell's OPC UA authority (plugcell certs opcua)
    await clientCertificateManager.initialize();
    const { readCertificate } = require("node-opcua-crypto");
    await clientCertificateManager.addIssuer(readCertificate(options.trustCa), false, true);
    if (options.trustCrl) {
      const { readCertificateRevocationList } = require("node-opcua-crypto");
      await clientCertificateManager.addRevocationList(
        await readCertificateRevocationList(options.trustCrl), "trusted");
    }
  }
  const settings = {
    endpointMustExist: false,
    connectionStrategy: { maxRetry: 0, initialDelay: 100, maxDelay: 200 },
    requestedSessionTimeout: 60000,
    clientCertificateManager,
  };
  if (options.secure) {
    settings.securityMode = MessageSecurityMode.SignAndEncrypt;
    settings.securityPolicy = SecurityPolicy.Basic256Sha256;
    settings.certificateFile = options.certificate;
    settings.privateKeyFile = options.privateKey;
    settings.applicationUri = options.applicationUri;
  }
  const client = OPCUAClient.create(settings);
  await client.connect(endpoint);
  const identity = options.user
    ? { type: UserTokenType.UserName, userName: options.user, password: options.password }
    : { type: UserTokenType.Anonymous };
  let session;
  try {
    session = await client.createSession(identity);
  } catch (err) {
    await client.disconnect();
    throw err;
  }
  const namespaces = await session.readNamespaceArray();
  const ns = namespaces.indexOf(`urn:plugcell:cell:${cell}`);
  if (ns < 0) throw new Error(`namespace of cell ${cell} not found in ${namespaces}`);
  const id = (p) => `ns=${ns};s=Cell${p ? "/" + p : ""}`;
  return { client, session, ns, id };
}

async function close({ client, session }) {
  await session.close();
  await client.disconnect();
}

async function read(session, nodeId) {
  const dv = await session.read({ nodeId, attributeId: AttributeIds.Value });
  if (dv.statusCode.isNotGood()) throw new Error(`read ${nodeId}: ${dv.statusCode.name}`);
  return dv.value.value;
}

function plain(value) {
  if (value === null || value === undefined) return value;
  if (ArrayBuffer.isView(value)) return Array.from(value);
  if (Array.isArray(value)) return value.map(plain);
  if (typeof value === "bigint") return Number(value);
  return value;
}

async function call(session, objectId, methodId, inputArguments) {
  const result = await session.call({ objectId, methodId, inputArguments });
  return {
    status: statusName(result.statusCode),
    inputResults: (result.inputArgumentResults || []).map(statusName),
    diagnostics: (result.inputArgumentDiagnosticInfos || []).map((d) => (d && d.additionalInfo) || ""),
    // every method's last output: Reason (String), why the call failed ("" if it did not)
    reason: (result.outputArguments || []).length
      ? result.outputArguments[result.outputArguments.length - 1].value : null,
    outputs: (result.outputArguments || []).map((v) => ({
      dataType: DataType[v.dataType], arrayType: v.arrayType, dimensions: v.dimensions || null,
      value: v.value,
    })),
  };
}

function summary(output) {
  const values = plain(output.value);
  const flat = Array.isArray(values) ? values : [values];
  let min = Infinity, max = -Infinity;
  for (const v of flat) { if (v < min) min = v; if (v > max) max = v; }
  return { dataType: output.dataType, dimensions: output.dimensions, length: flat.length, min, max };
}

async function subscription(session) {
  return ClientSubscription.create(session, {
    requestedPublishingInterval: 50, requestedLifetimeCount: 1200, requestedMaxKeepAliveCount: 20,
    maxNotificationsPerPublish: 0, publishingEnabled: true, priority: 1,
  });
}

// Collect `count` value changes of `nodeId` (the first, initial value is skipped).
async function watch(sub, nodeId, count, keepValues) {
  const item = ClientMonitoredItem.create(sub, { nodeId, attributeId: AttributeIds.Value },
    { samplingInterval: 0, queueSize: 100, discardOldest: true }, TimestampsToReturn.Both);
  const seen = [];
  let first = true;
  await new Promise((resolve, reject) => {
    item.on("err", (e) => reject(new Error(`monitor ${nodeId}: ${e}`)));
    item.on("changed", (dv) => {
      if (first) { first = false; return; }
      const v = dv.value;
      const raw = v.value;
      seen.push({
        dataType: DataType[v.dataType], dimensions: v.dimensions || null,
        length: raw !== null && typeof raw === "object" && "length" in raw ? raw.length : 1,
        value: keepValues ? plain(raw) : undefined,
      });
      if (seen.length >= count) resolve();
    });
  });
  await item.terminate();
  return seen;
}

async function events(sub, ns) {
  const fields = ["Message", "SourceName", "Severity", `${ns}:Service`, `${ns}:Command`,
                  `${ns}:Sender`, `${ns}:State`, `${ns}:Reason`];
  const item = ClientMonitoredItem.create(sub,
    { nodeId: "i=2253", attributeId: AttributeIds.EventNotifier },
    { queueSize: 100, filter: constructEventFilter(fields) }, TimestampsToReturn.Both);
  const got = [];
  const live = new Promise((resolve, reject) => {
    item.on("initialized", resolve);
    item.on("err", (e) => reject(new Error(`event monitor: ${e}`)));
  });
  item.on("changed", (values) => {
    const event = {};
    fields.forEach((f, i) => { event[f.replace(/^\d+:/, "")] = plain(values[i].value); });
    if (event.Message && event.Message.text !== undefined) event.Message = event.Message.text;
    got.push(event);
  });
  await live;  // the monitored item exists: no event of the calls below is missed
  return { item, got };
}

async function until(predicate, ms, what) {
  const deadline = Date.now() + ms;
  while (!predicate()) {
    if (Date.now() > deadline) throw new Error(`${what} not seen within ${ms} ms`);
    await new Promise((resolve) => setTimeout(resolve, 20));
  }
}

const scenarios = {
  // browse the cell; read a camera's DeviceInfo and the declaration of SnapShot
  async browse(c) {
    const { session, id } = c;
    const cellRefs = (await session.browse(id())).references;
    const services = cellRefs.map((r) => r.browseName.name).sort();
    const children = (await session.browse(id("CAMERA"))).references;
    const names = children.map((r) => r.browseName.name);
    const info = {};
    for (const key of ["Kind", "Vendor", "Info", "Instance", "Manufacturer", "Model",
                       "DeviceState", "ConnectionState", "DeviceHealth", "Partners"]) {
      info[key] = plain(await read(session, id(`CAMERA/${key}`)));
    }
    const argsNode = (await session.browse(id("CAMERA/SnapShot"))).references
      .find((r) => r.browseName.name === "InputArguments");
    const declared = (await read(session, argsNode.nodeId)).map((a) => ({
      name: a.name, dataType: a.dataType.value, valueRank: a.valueRank,
      arrayDimensions: plain(a.arrayDimensions),
    }));
    const outNode = (await session.browse(id("CAMERA/SnapShot"))).references
      .find((r) => r.browseName.name === "OutputArguments");
    const output = (await read(session, outNode.nodeId)).map((a) => ({
      name: a.name, dataType: a.dataType.value, valueRank: a.valueRank,
      arrayDimensions: plain(a.arrayDimensions),
    }));
    return { services, children: names, info, inputArguments: declared, outputArguments: output };
  },

  async snapshot(c) {
    const r = await call(c.session, c.id("CAMERA"), c.id("CAMERA/SnapShot"), [str(""), int32(50)]);
    return { status: r.status, image: r.outputs.length ? summary(r.outputs[0]) : null };
  },

  // wrong types and sizes, an unknown method, then a good call: the server keeps serving
  async bad(c) {
    const { session, id } = c;
    const cam = id("CAMERA");
    const snap = id("CAMERA/SnapShot");
    const out = {};
    out.double = await call(session, cam, snap, [str(""), double(5.5)]);
    out.vector = await call(session, cam, snap, [str(""),
      { dataType: DataType.Int32, arrayType: 1, value: new Int32Array([1, 2]) }]);
    out.option = await call(session, cam, snap, [int32(3), int32(5)]);
    out.missing = await call(session, cam, snap, [str("")]);
    out.tooMany = await call(session, cam, snap, [str(""), int32(5), int32(6)]);
    out.unknown = await call(session, cam, id("CAMERA/Teleport"), [str("")]);
    out.good = (await call(session, cam, snap, [str(""), int32(5)])).status;
    return out;
  },

  // MovieShot: a process object; subscribe to its Data, then Stop
  async movie(c) {
    const { session, id } = c;
    const r = await call(session, id("CAMERA"), id("CAMERA/MovieShot"), [str(""), int32(5)]);
    if (r.status !== "Good") return { status: r.status };
    const process = r.outputs[0].value.toString();
    const sub = await subscription(session);
    const frames = await watch(sub, `${process}/Data`, 3, false);
    const busy = await read(session, id("CAMERA/DeviceState"));  // live: StateUpdate
    const stop = await call(session, process, `${process}/Stop`, []);
    const state = await read(session, `${process}/State`);
    const counted = await read(session, `${process}/Frames`);
    const stopAgain = await call(session, process, `${process}/Stop`, []);
    await sub.terminate();
    // ConnectionState follows the camera's ConnectionUpdate notifications
    const connection = async (want) => {
      const deadline = Date.now() + 5000;
      while (Date.now() < deadline) {
        if (await read(session, id("CAMERA/ConnectionState")) === want) return want;
        await new Promise((resolve) => setTimeout(resolve, 50));
      }
      return await read(session, id("CAMERA/ConnectionState"));
    };
    const disconnect = (await call(session, id("CAMERA"), id("CAMERA/Disconnect"), [str("")])).status;
    const offline = await connection("Offline");
    const reconnect = (await call(session, id("CAMERA"), id("CAMERA/Connect"), [str("")])).status;
    const online = await connection("Online");
    return { status: r.status, process, frames, busy, stop: stop.status, state, counted,
             stopAgain: stopAgain.status, disconnect, offline, reconnect, online };
  },

  // a MultipleData started and left running: closing the session must stop it
  async abandon(c) {
    const { session, id } = c;
    const r = await call(session, id("CAMERA"), id("CAMERA/MovieShot"), [str(""), int32(5)]);
    if (r.status !== "Good") return { status: r.status };
    const sub = await subscription(session);
    const frames = await watch(sub, `${r.outputs[0].value.toString()}/Data`, 1, false);
    return { status: r.status, frames: frames.length };  // closed without Stop
  },

  // a process that fails: a Bad status and a ProcessEventType event with the reason
  async events(c) {
    const { session, id, ns } = c;
    const sub = await subscription(session);
    const { item, got } = await events(sub, ns);
    const fail = await call(session, id("CAMERA"), id("CAMERA/MovieShot"), [str(""), int32(5000)]);
    const bad = await call(session, id("CAMERA"), id("CAMERA/SnapShot"), [str(""), double(1)]);
    const good = await call(session, id("CAMERA"), id("CAMERA/SnapShot"), [str(""), int32(1)]);
    await until(() => got.filter((e) => e.State === "Completed").length >= 1, 5000, "events");
    await item.terminate();
    await sub.terminate();
    return { fail: fail.status, failReason: fail.reason, bad: bad.status, badReason: bad.reason,
             good: good.status, goodReason: good.reason, events: got };
  },

  // a tracker: Set Base/Set Probe/Move with Double[6], then a Continuous Measurement
  async track(c) {
    const { session, id } = c;
    const t = id("TRACKER");
    const vec = (v) => ({ dataType: DataType.Double, arrayType: 1, value: new Float64Array(v) });
    const o = options.tracker;
    const setup = [];
    setup.push((await call(session, t, id("TRACKER/Set Base"), [str("euler2tr"), vec(o.base)])).status);
    setup.push((await call(session, t, id("TRACKER/Set Probe"), [str("euler2tr"), vec(o.probe)])).status);
    setup.push((await call(session, t, id("TRACKER/Move"), [str(""), vec(o.pose)])).status);
    const r = await call(session, t, id("TRACKER/Continuous Measurement"),
                         [str("tr2euler"), int32(20)]);
    if (r.status !== "Good") return { setup, status: r.status };
    const process = r.outputs[0].value.toString();
    const sub = await subscription(session);
    const samples = await watch(sub, `${process}/Data`, 3, true);
    const stop = await call(session, process, `${process}/Stop`, []);
    await sub.terminate();
    return { setup, status: r.status, samples, stop: stop.status,
             state: await read(session, `${process}/State`) };
  },

  // a robot's flange pose (plugcell's variable on its OPC 40010 MotionDevice)
  async robot(c) {
    const { session, ns } = c;
    return { flange: plain(await read(session,
      `ns=${ns};s=DeviceSet.ROBOT.MotionDevices.ROBOT.FlangePose`)) };
  },

  // a generic client that knows only the companion specifications: every object below
  // Objects by its type (DI DeviceType and its subtypes, OPC 40010 MotionDeviceType),
  // then each motion device's identification and axes' ActualPosition / ActualSpeed
  async types(c) {
    const { session } = c;
    const namespaces = await session.readNamespaceArray();
    const di = namespaces.indexOf("http://opcfoundation.org/UA/DI/");
    const rob = namespaces.indexOf("http://opcfoundation.org/UA/Robotics/");
    if (di < 0 || rob < 0) throw new Error(`no DI or Robotics namespace in ${namespaces}`);
    const deviceType = `ns=${di};i=1002`, motionDeviceType = `ns=${rob};i=1004`;
    const supertypes = new Map();
    async function isA(typeId, wanted) {  // follow HasSubtype inverse up to BaseObjectType
      let t = typeId;
      for (let depth = 0; depth < 20 && t; depth += 1) {
        if (t === wanted) return true;
        if (!supertypes.has(t)) {
          const up = await session.browse({ nodeId: t, browseDirection: 1 /* Inverse */,
            referenceTypeId: "HasSubtype", includeSubtypes: false, resultMask: 63 });
          supertypes.set(t, up.references.length ? up.references[0].nodeId.toString() : null);
        }
        t = supertypes.get(t);
      }
      return false;
    }
    const seen = new Set(), devices = [], motionDevices = [];
    async function walk(nodeId, depth) {
      if (seen.has(nodeId) || depth > 12) return;
      seen.add(nodeId);
      const r = await session.browse({ nodeId, browseDirection: 0 /* Forward */,
        referenceTypeId: "HierarchicalReferences", includeSubtypes: true, nodeClassMask: 1,
        resultMask: 63 });
      for (const ref of r.references) {
        const id = ref.nodeId.toString();
        const type = ref.typeDefinition.toString();
        if (!seen.has(id)) {
          if (await isA(type, deviceType)) devices.push({ nodeId: id, name: ref.browseName.name });
          if (type === motionDeviceType) motionDevices.push({ nodeId: id, name: ref.browseName.name });
        }
        await walk(id, depth + 1);
      }
    }
    await walk("i=85", 0);
    const qn = (ns, name) => ({ namespaceIndex: ns, name });
    async function at(start, path) {
      const r = await session.translateBrowsePath({ startingNode: start, relativePath: {
        elements: path.map(([ns, name]) => ({ referenceTypeId: "i=33",
          isInverse: false, includeSubtypes: true, targetName: qn(ns, name) })) } });
      if (r.statusCode.isNotGood()) throw new Error(`${start} ${JSON.stringify(path)}: ${r.statusCode.name}`);
      return r.targets[0].targetId.toString();
    }
    async function value(nodeId) {
      const dv = await session.read({ nodeId, attributeId: AttributeIds.Value });
      return { status: dv.statusCode.name, value: plain(dv.value.value) };
    }
    const text = (v) => (v && v.text !== undefined ? v.text : v);
    for (const md of motionDevices) {
      for (const key of ["Manufacturer", "Model", "SerialNumber", "ProductCode"]) {
        md[key] = text((await value(await at(md.nodeId, [[di, key]]))).value);
      }
      md.category = (await value(await at(md.nodeId, [[rob, "MotionDeviceCategory"]]))).value;
      const axes = await session.browse({ nodeId: await at(md.nodeId, [[rob, "Axes"]]),
        referenceTypeId: "HierarchicalReferences", includeSubtypes: true, nodeClassMask: 1,
        resultMask: 63 });
      md.axes = [];
      for (const ref of axes.references.sort((a, b) => a.browseName.name.localeCompare(b.browseName.name))) {
        const axis = ref.nodeId.toString();
        const pos = await at(axis, [[di, "ParameterSet"], [rob, "ActualPosition"]]);
        const units = await value(await at(pos, [[0, "EngineeringUnits"]]));
        md.axes.push({ name: ref.browseName.name, type: ref.typeDefinition.toString() === `ns=${rob};i=16601`,
          position: await value(pos),
          speed: await value(await at(axis, [[di, "ParameterSet"], [rob, "ActualSpeed"]])),
          unit: units.value && units.value.displayName ? units.value.displayName.text : null });
      }
      md.powerTrains = (await session.browse({ nodeId: await at(md.nodeId, [[rob, "PowerTrains"]]),
        referenceTypeId: "HierarchicalReferences", includeSubtypes: true, nodeClassMask: 1 }))
        .references.length;
    }
    return { devices: devices.map((d) => d.name).sort(), motionDevices };
  },

  // security: who may log in, who may call
  async login(c) {
    const r = await call(c.session, c.id("CAMERA"), c.id("CAMERA/SnapShot"), [str(""), int32(1)]);
    return { status: r.status, reason: r.reason,
             image: r.status === "Good" ? summary(r.outputs[0]) : null };
  },
};

// one connection with `settings`: the scenario's result, or {refused: reason}
async function attempt(fn, settings) {
  let c;
  try {
    c = await open(settings);
  } catch (err) {  // a refused connection or session is a result the tests look at
    return { refused: String(err.message || err) };
  }
  const result = await fn(c);
  await close(c);
  return result;
}

(async () => {
  const fn = scenarios[scenario];
  if (!fn) throw new Error(`unknown scenario ${scenario}`);
  // OPTIONS.attempts: several connections in one run, each with its own settings
  let result;
  if (options.attempts) {
    result = [];
    for (const extra of options.attempts) result.push(await attempt(fn, { ...options, ...extra }));
  } else {
    result = await attempt(fn, options);
  }
  process.stdout.write(JSON.stringify(result) + "\n");
  clearTimeout(limit);
  process.exit(0);
})().catch((err) => {
  process.stderr.write(`client.js ${scenario}: ${err.stack || err}\n`);
  process.exit(1);
});
