// A gripper behind an OPC UA server, written with node-opcua (an independent stack):
// object Gripper with methods Open() and Close(force: Double) and variables Force
// (Double, N) and Closed (Boolean), in namespace urn:plugcell:test:gripper.
//
//   node gripper_server.js PORT [CA_PEM CA_CRL] [OPTIONS-JSON]
//
// With CA_PEM and CA_CRL (the cell's OPC UA authority and its revocation list) the server
// offers only Basic256Sha256 SignAndEncrypt, trusts application certificates of that
// authority and accepts the one user plc / gripper-pw (no anonymous sessions).
// OPTIONS {certificate, privateKey, applicationUri}: the server's own application
// certificate (PEM) and URI (default: node-opcua's self-signed certificate of its PKI
// folder) — the tests' servers with a trusted, a rotated, an expired or a foreign one.
//
// prints {"listening": URL} when ready and one {"called": …} line per method call;
// runs until killed.  Close ramps Force up to the asked force in 5 steps of 20 ms.
"use strict";

const {
  OPCUAServer, Variant, DataType, StatusCodes, OPCUACertificateManager, SecurityPolicy,
  MessageSecurityMode,
} = require("node-opcua");
const os = require("os");
const path = require("path");

const port = Number(process.argv[2]);
const rest = process.argv.slice(3);
const own = rest.length && rest[rest.length - 1].startsWith("{") ? JSON.parse(rest.pop()) : {};
const [caPem, caCrl] = rest;

function say(obj) { process.stdout.write(JSON.stringify(obj) + "\n"); }

(async () => {
  const pki = path.join(os.tmpdir(),
    `plugcell-opcua-test-server-pki-${os.userInfo().uid}${caPem ? "-secure" : ""}`);
  const serverCertificateManager = new OPCUACertificateManager({
    rootFolder: pki, automaticallyAcceptUnknownCertificate: !caPem,
  });
  const options = {
    port, hostname: "127.0.0.1", resourcePath: "/gripper", serverCertificateManager,
    buildInfo: { productName: "test gripper", manufacturerName: "plugcell tests" },
  };
  if (own.certificate) {
    Object.assign(options, {
      certificateFile: own.certificate, privateKeyFile: own.privateKey,
      serverInfo: { applicationUri: own.applicationUri },
    });
  }
  if (caPem) {
    await serverCertificateManager.initialize();
    const { readCertificate, readCertificateRevocationList } = require("node-opcua-crypto");
    await serverCertificateManager.addIssuer(readCertificate(caPem), false, true);
    await serverCertificateManager.addRevocationList(await readCertificateRevocationList(caCrl),
                                                     "trusted");
    Object.assign(options, {
      securityPolicies: [SecurityPolicy.Basic256Sha256],
      securityModes: [MessageSecurityMode.SignAndEncrypt],
      allowAnonymous: false,
      userManager: { isValidUser: (user, password) => user === "plc" && password === "gripper-pw" },
    });
  }
  const server = new OPCUAServer(options);
  await server.initialize();
  const space = server.engine.addressSpace;
  const ns = space.registerNamespace("urn:plugcell:test:gripper");
  const gripper = ns.addObject({ organizedBy: space.rootFolder.objects, browseName: "Gripper",
                                 nodeId: "s=Gripper" });
  let force = 0.0;
  let closed = false;
  ns.addVariable({
    componentOf: gripper, browseName: "Force", nodeId: "s=Gripper.Force", dataType: "Double",
    minimumSamplingInterval: 10,
    value: { get: () => new Variant({ dataType: DataType.Double, value: force }) },
  });
  ns.addVariable({
    componentOf: gripper, browseName: "Closed", nodeId: "s=Gripper.Closed", dataType: "Boolean",
    value: { get: () => new Variant({ dataType: DataType.Boolean, value: closed }) },
  });
  const open = ns.addMethod(gripper, { browseName: "Open", nodeId: "s=Gripper.Open",
                                       inputArguments: [], outputArguments: [] });
  open.bindMethod((inputArguments, context, callback) => {
    force = 0.0;
    closed = false;
    say({ called: "Open" });
    callback(null, { statusCode: StatusCodes.Good, outputArguments: [] });
  });
  const close = ns.addMethod(gripper, {
    browseName: "Close", nodeId: "s=Gripper.Close",
    inputArguments: [{ name: "Force", dataType: DataType.Double, description: "N" }],
    outputArguments: [{ name: "Reached", dataType: DataType.Double, description: "N" }],
  });
  close.bindMethod(async (inputArguments, context, callback) => {
    const target = inputArguments[0].value;
    say({ called: "Close", force: target });
    if (!(target > 0 && target <= 100)) {
      callback(null, { statusCode: StatusCodes.BadOutOfRange, outputArguments: [] });
      return;
    }
    for (let step = 1; step <= 5; step += 1) {
      force = (target * step) / 5;
      await new Promise((resolve) => setTimeout(resolve, 20));
    }
    closed = true;
    callback(null, { statusCode: StatusCodes.Good,
                     outputArguments: [{ dataType: DataType.Double, value: force }] });
  });
  setInterval(() => { if (closed) force += 0.001; }, 50);  // the jaw creeps: a live value
  await server.start();
  say({ listening: server.getEndpointUrl() });
})().catch((err) => {
  process.stderr.write(`gripper_server.js: ${err.stack || err}\n`);
  process.exit(1);
});
