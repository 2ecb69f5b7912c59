// node-opcua, an independent OPC UA client, against pendant's face (tests/test_opcua_node.py).
//
//   node client.js SPEC_JSON
//
// SPEC: {endpoint, cert, key (PEM files of the client's application certificate), pki (a
// folder for node-opcua's own certificate store), user, password | identityCert,
// identityKey, action}. Every result is one JSON line on stdout:
//   action "read-frame": ReadFrame("tool", n) and the Tool n/Frame variable  -> {frame, name, version, coords}
//   action "login": open a session and read the server's browse name        -> {ok} or {error}
//   action "subscribe": subscribe to a node (browse path) and print each value as it comes,
//     with the client's request count each second, until killed             -> {value} / {requests}
"use strict";

const {
  OPCUAClient, MessageSecurityMode, SecurityPolicy, UserTokenType, AttributeIds,
  OPCUACertificateManager, DataType, TimestampsToReturn, makeBrowsePath,
} = require("node-opcua");
const fs = require("fs");

const spec = JSON.parse(process.argv[2]);
const out = (obj) => process.stdout.write(JSON.stringify(obj) + "\n");

async function nsIndex(session, uri) {
  const dv = await session.read({ nodeId: "ns=0;i=2255", attributeId: AttributeIds.Value });
  const i = dv.value.value.indexOf(uri);
  if (i < 0) throw new Error(`namespace ${uri} not on the server`);
  return i;
}

async function resolve(session, path) {
  // path: ["ns-uri|Name", ...] from Objects
  const parts = [];
  for (const p of path) {
    const [uri, name] = p.split("|");
    parts.push(`/${await nsIndex(session, uri)}:${name}`);
  }
  const r = await session.translateBrowsePath(makeBrowsePath("ObjectsFolder", parts.join("")));
  if (!r.statusCode.isGood() || !r.targets || !r.targets.length) {
    throw new Error(`browse path ${path.join("/")}: ${r.statusCode.toString()}`);
  }
  return r.targets[0].targetId;
}

function identity() {
  if (spec.identityCert) {
    return {
      type: UserTokenType.Certificate,
      certificateData: fs.readFileSync(spec.identityCert),
      privateKey: fs.readFileSync(spec.identityKey, "utf8"),
    };
  }
  if (spec.user) return { type: UserTokenType.UserName, userName: spec.user, password: spec.password };
  return { type: UserTokenType.Anonymous };
}

function makeClient() {
  const manager = new OPCUACertificateManager({
    rootFolder: spec.pki, automaticallyAcceptUnknownCertificate: true,
  });
  return OPCUAClient.create({
    applicationName: "pendant-tests-node",
    applicationUri: spec.uri,
    securityMode: MessageSecurityMode.SignAndEncrypt,
    securityPolicy: SecurityPolicy.Basic256Sha256,
    certificateFile: spec.cert,
    privateKeyFile: spec.key,
    clientCertificateManager: manager,
    endpointMustExist: false,
    connectionStrategy: { initialDelay: 200, maxDelay: 1000, maxRetry: spec.action === "subscribe" ? 1000 : 0 },
    keepSessionAlive: true,
    requestedSessionTimeout: 60000,
  });
}

async function main() {
  const client = makeClient();
  try {
    await client.connect(spec.endpoint);
  } catch (err) {
    out({ error: `connect: ${err.message}` });
    process.exit(3);
  }
  let session;
  try {
    session = await client.createSession(identity());
  } catch (err) {
    out({ error: `session: ${err.message}` });
    await client.disconnect();
    process.exit(4);
  }
  const PENDANT = "urn:pendant:opcua";
  if (spec.action === "login") {
    const dv = await session.read({ nodeId: "ns=0;i=2253", attributeId: AttributeIds.BrowseName });
    out({ ok: dv.value.value.name });
  } else if (spec.action === "read-frame") {
    const obj = await resolve(session, [`${PENDANT}|Pendant`, `${PENDANT}|${spec.controller}`]);
    const method = await resolve(session, [`${PENDANT}|Pendant`, `${PENDANT}|${spec.controller}`, `${PENDANT}|ReadFrame`]);
    const res = await session.call({
      objectId: obj, methodId: method,
      inputArguments: [{ dataType: DataType.String, value: "tool" }, { dataType: DataType.Int32, value: spec.number }],
    });
    if (!res.statusCode.isGood()) throw new Error(`ReadFrame: ${res.statusCode.toString()}`);
    const [name, , frame, version] = res.outputArguments.map((v) => v.value);
    const xNode = await resolve(session, [`${PENDANT}|Pendant`, `${PENDANT}|${spec.controller}`,
      `${PENDANT}|Tools`, `${PENDANT}|Tool${spec.number}`, `${PENDANT}|Frame`,
      "http://opcfoundation.org/UA/|CartesianCoordinates", "http://opcfoundation.org/UA/|X"]);
    const x = await session.read({ nodeId: xNode, attributeId: AttributeIds.Value });
    out({ name, frame: Array.from(frame), version: Array.isArray(version) ? version[0] * 2 ** 32 + version[1] : Number(version), // UInt64: [high, low]
          x: x.value.value,
          xStatus: x.statusCode.name });
  } else if (spec.action === "subscribe") {
    const nodeId = await resolve(session, spec.path);
    const sub = await session.createSubscription2({
      requestedPublishingInterval: 100, requestedLifetimeCount: 600, requestedMaxKeepAliveCount: 10,
      maxNotificationsPerPublish: 100, publishingEnabled: true, priority: 1,
    });
    const item = await sub.monitor({ nodeId, attributeId: AttributeIds.Value },
      { samplingInterval: 100, discardOldest: true, queueSize: 10 }, TimestampsToReturn.Both);
    item.on("changed", (dv) => out({ value: dv.value.value, status: dv.statusCode.name }));
    client.on("connection_reestablished", () => out({ event: "reconnected" }));
    session.on("session_restored", () => out({ event: "session_restored" }));
    setInterval(() => out({ requests: client.transactionsPerformed }), 1000);
    out({ event: "subscribed" });
    await new Promise(() => {});
  }
  await session.close();
  await client.disconnect();
}

main().catch((err) => { out({ error: err.message }); process.exit(5); });
