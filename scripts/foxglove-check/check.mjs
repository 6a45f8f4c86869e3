#!/usr/bin/env node
// Reads chaosd's output with the libraries the Foxglove app reads data with, and says whether
// Foxglove would take every message.
//
//   node check.mjs file RUN.mcap                  an MCAP recording
//   node check.mjs live ws://HOST:PORT SECONDS    the live view (Foxglove WebSocket protocol)
//
// `file` opens the recording with @mcap/core's indexed reader as Foxglove opens a local file
// (LZ4 chunks through @foxglove/wasm-lz4, CRCs checked), reads it once more in file order with
// the streaming reader, and compares both with the file's Statistics record. `live` connects
// with @foxglove/ws-protocol's client (subprotocol foxglove.websocket.v1), subscribes to every
// advertised channel for SECONDS, unsubscribes and closes. Either way every message is decoded
// with the decoder Foxglove picks for its channel: ros2msg + CDR with @foxglove/rosmsg and
// @foxglove/rosmsg2-serialization (no byte may be left over), JSON with JSON.parse, validated
// with ajv against the channel's own JSON Schema and, for a foxglove.* schema name, against the
// official one from @foxglove/schemas. A JSON Schema must also be one Foxglove's schema reader
// takes (`foxgloveReadsSchema`). Log times may never go back on a channel.
//
// Prints one JSON line: per topic the schema, encodings, count and first and last log time (ns
// since the Unix epoch, as strings: they exceed 2^53), the span of all of them, and the last
// /joint_states decoded (JS prints a float as the shortest decimal that reads back exactly).
// Otherwise exits 1 with one line naming the channel and the fault. tests/tests/mcap_live.rs and
// foxglove_live.rs run it when CHAOSD_FOXGLOVE_CHECK names this folder (after `npm ci`).

import { createReadStream } from "node:fs";
import { open } from "node:fs/promises";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import lz4 from "@foxglove/wasm-lz4";
import { parse as parseRosMsg } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import official from "@foxglove/schemas/jsonschema.js";
import Ajv from "ajv";
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;

/** Channels chaosd publishes only when something happens: a short live check may see none. */
const ON_CHANGE = new Set(["/chaosd/events"]);

/** How long the live view may take to say hello (serverInfo, advertise). */
const HELLO_MS = 10_000;

function fail(message) {
  throw new Error(message);
}

const ajv = new Ajv({ allErrors: true, strict: true });

/** MCAP chunk decompression as Foxglove does it (chaosd writes LZ4 chunks). */
const decompressHandlers = {
  lz4: (buffer, size) => lz4(buffer, Number(size)),
};

/**
 * Foxglove turns a channel's JSON Schema into the fields its panels offer; a schema its reader
 * cannot read drops the channel ("Error in topic …"). That reader is part of the app
 * (mcap-support's parseJsonSchema), not on npm, so its rules are restated here: every object
 * lists its `properties`; a field is a boolean, a string (plain or base64), a number, an
 * integer, an object, an array of one of those, or a `oneOf` of numeric constants (an enum).
 * Every official foxglove.* schema passes.
 */
function foxgloveReadsSchema(schema, path) {
  if (schema?.type !== "object") {
    fail(`${path}: Foxglove's schema reader wants "type": "object", not ${schema?.type}`);
  }
  if (schema.properties === null || typeof schema.properties !== "object") {
    fail(`${path}: an object without "properties" (Foxglove's schema reader fails on it)`);
  }
  for (const [name, field] of Object.entries(schema.properties)) {
    const at = `${path}.${name}`;
    if (Array.isArray(field.oneOf)) {
      if (!field.oneOf.every((alternative) => typeof alternative.const === "number")) {
        fail(`${at}: a oneOf whose alternatives are not all numeric constants`);
      }
      continue;
    }
    const isArray = field.type === "array";
    const item = isArray ? field.items ?? {} : field;
    switch (item.type) {
      case "boolean":
      case "number":
      case "integer":
        break;
      case "string":
        if (item.contentEncoding !== undefined && (isArray || item.contentEncoding !== "base64")) {
          fail(`${at}: contentEncoding ${item.contentEncoding} is not read`);
        }
        break;
      case "object":
        foxgloveReadsSchema(item, at);
        break;
      default:
        fail(`${at}: type ${JSON.stringify(item.type)}${isArray ? " (array items)" : ""} not read`);
    }
  }
}

/**
 * The decoder Foxglove picks for a channel, from its message encoding and schema encoding, with
 * the validation on top: (bytes) => value, throwing on any fault. Fails at once for a channel
 * Foxglove could not decode at all.
 */
function decoderFor({ topic, messageEncoding, schemaName, schemaEncoding, schemaText }) {
  const where = `${topic} (${schemaName || "no schema"})`;
  if (messageEncoding === "cdr") {
    if (schemaEncoding !== "ros2msg") {
      fail(`${where}: CDR with schema encoding '${schemaEncoding}' (chaosd writes ros2msg)`);
    }
    const reader = new MessageReader(parseRosMsg(schemaText, { ros2: true }));
    return (bytes) => {
      const message = reader.readMessage(bytes);
      if (reader.lastReadHadTrailingBytes()) {
        const left = bytes.byteLength - reader.lastReadByteLength();
        throw new Error(`${left} bytes left after the message: it does not match its schema`);
      }
      return message;
    };
  }
  if (messageEncoding === "json") {
    if (schemaEncoding !== "jsonschema") {
      fail(`${where}: JSON with schema encoding '${schemaEncoding}' (chaosd writes jsonschema)`);
    }
    const own = JSON.parse(schemaText);
    foxgloveReadsSchema(own, schemaName);
    const validators = [["its own schema", ajv.compile(own)]];
    if (schemaName.startsWith("foxglove.")) {
      const schema = official[schemaName.slice("foxglove.".length)];
      if (schema === undefined) fail(`${where}: @foxglove/schemas has no ${schemaName}`);
      validators.push([`the official ${schemaName}`, ajv.compile(schema)]);
    }
    const text = new TextDecoder("utf-8", { fatal: true });
    return (bytes) => {
      const value = JSON.parse(text.decode(bytes));
      for (const [what, validate] of validators) {
        if (!validate(value)) {
          throw new Error(`invalid against ${what}: ${ajv.errorsText(validate.errors)}`);
        }
      }
      return value;
    };
  }
  fail(`${where}: no decoder for message encoding '${messageEncoding}' (Foxglove: unsupported)`);
}

/** What is counted of one topic (`last` and `lastTime` are not printed). */
function tally(info) {
  return {
    schema: info.schemaName,
    schema_encoding: info.schemaEncoding,
    message_encoding: info.messageEncoding,
    count: 0,
    first_log_time_ns: null,
    last_log_time_ns: null,
    last: undefined,
    lastTime: undefined,
  };
}

/** Decodes one message of `channel` and counts it; its log time may not go back. */
function take(channel, topics, logTime, bytes) {
  const { info, decode } = channel;
  const entry = topics[info.topic];
  let value;
  try {
    value = decode(bytes);
  } catch (e) {
    const which = `message ${entry.count + 1} (log time ${logTime})`;
    fail(`${info.topic} (${info.schemaName}), ${which}: ${e.message}`);
  }
  if (entry.lastTime !== undefined && logTime < entry.lastTime) {
    fail(`${info.topic}: log time goes back (${entry.lastTime} then ${logTime})`);
  }
  entry.count += 1;
  entry.first_log_time_ns ??= logTime.toString();
  entry.last_log_time_ns = logTime.toString();
  entry.lastTime = logTime;
  entry.last = value;
}

/** The earliest and latest log time of any message (ns), or undefined without messages. */
function span(topics) {
  const seen = Object.values(topics).filter((t) => t.count > 0);
  if (seen.length === 0) return [undefined, undefined];
  const firsts = seen.map((t) => BigInt(t.first_log_time_ns));
  const lasts = seen.map((t) => BigInt(t.last_log_time_ns));
  return [firsts.reduce((a, b) => (b < a ? b : a)), lasts.reduce((a, b) => (b > a ? b : a))];
}

/** The printed result: the tallies, their span and the last joint state. */
function summary(topics, extra) {
  const shown = {};
  for (const [topic, { last, lastTime, ...rest }] of Object.entries(topics)) shown[topic] = rest;
  const [first, last] = span(topics);
  const js = topics["/joint_states"]?.last;
  const stamp = js && BigInt(js.header.stamp.sec) * 10n ** 9n + BigInt(js.header.stamp.nanosec);
  return {
    ...extra,
    first_log_time_ns: first?.toString() ?? null,
    last_log_time_ns: last?.toString() ?? null,
    topics: shown,
    last_joint_state: js
      ? {
          stamp_ns: stamp.toString(),
          frame_id: js.header.frame_id,
          name: js.name,
          position: Array.from(js.position),
          velocity: Array.from(js.velocity),
          effort: Array.from(js.effort),
        }
      : null,
  };
}

/** An MCAP file as @mcap/core's readable: random reads, as Foxglove reads a local file. */
function readable(handle) {
  return {
    size: async () => BigInt((await handle.stat()).size),
    read: async (offset, size) => {
      const buffer = new Uint8Array(Number(size));
      const { bytesRead } = await handle.read(buffer, 0, buffer.length, Number(offset));
      if (bytesRead !== buffer.length) fail(`short read at byte ${offset}`);
      return buffer;
    },
  };
}

async function checkFile(path) {
  await lz4.isLoaded;
  const handle = await open(path, "r");
  try {
    const reader = await McapIndexedReader.Initialize({
      readable: readable(handle),
      decompressHandlers,
    });
    if (reader.chunkIndexes.length === 0) {
      fail("no chunk index: Foxglove would have to read the file from start to end");
    }
    const channels = new Map();
    const topics = {};
    for (const channel of reader.channelsById.values()) {
      const schema = reader.schemasById.get(channel.schemaId);
      const info = {
        topic: channel.topic,
        messageEncoding: channel.messageEncoding,
        schemaName: schema?.name ?? "",
        schemaEncoding: schema?.encoding ?? "",
        schemaText: schema ? new TextDecoder().decode(schema.data) : "",
      };
      if (topics[info.topic]) fail(`two channels on ${info.topic}`);
      topics[info.topic] = tally(info);
      channels.set(channel.id, { info, decode: decoderFor(info) });
    }
    for await (const m of reader.readMessages({ validateCrcs: true })) {
      take(channels.get(m.channelId), topics, m.logTime, m.data);
    }
    await inFileOrder(path, reader, topics);
    checkStatistics(reader, topics);
    return summary(topics, {
      mode: "file",
      file: path,
      chunks: reader.chunkIndexes.length,
      compression: [...new Set(reader.chunkIndexes.map((c) => c.compression))],
      metadata: reader.metadataIndexes.map((m) => m.name),
    });
  } finally {
    await handle.close();
  }
}

/**
 * The indexed reader hands messages over sorted by log time; the streaming reader (Foxglove's
 * for a file without an index) reads them as written: per channel, the same count, and log times
 * that never go back in the file either.
 */
async function inFileOrder(path, indexed, topics) {
  const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true });
  const count = new Map();
  const last = new Map();
  const drain = () => {
    for (let r; (r = stream.nextRecord()); ) {
      if (r.type !== "Message") continue;
      const topic = indexed.channelsById.get(r.channelId)?.topic;
      if (topic === undefined) fail(`a message on channel ${r.channelId}, not in the index`);
      if (last.has(topic) && r.logTime < last.get(topic)) {
        fail(`${topic}: in file order, log time goes back (${last.get(topic)} then ${r.logTime})`);
      }
      last.set(topic, r.logTime);
      count.set(topic, (count.get(topic) ?? 0) + 1);
    }
  };
  for await (const piece of createReadStream(path)) {
    stream.append(piece);
    drain();
  }
  if (!stream.done()) fail("the streaming reader did not reach the footer");
  for (const [topic, { count: indexedCount }] of Object.entries(topics)) {
    const streamed = count.get(topic) ?? 0;
    if (streamed !== indexedCount) {
      fail(`${topic}: ${indexedCount} messages through the index, ${streamed} in file order`);
    }
  }
}

/** The Statistics record: the counts and time range Foxglove shows before it reads a message. */
function checkStatistics(reader, topics) {
  const stats = reader.statistics;
  if (stats === undefined) fail("no Statistics record");
  for (const [id, n] of stats.channelMessageCounts) {
    const { topic } = reader.channelsById.get(id);
    if (Number(n) !== topics[topic].count) {
      fail(`${topic}: Statistics says ${n} messages, ${topics[topic].count} were read`);
    }
  }
  const [first, last] = span(topics);
  const { messageStartTime: start, messageEndTime: end } = stats;
  if (first !== undefined && (start !== first || end !== last)) {
    fail(`Statistics spans ${start}..${end}, the messages ${first}..${last}`);
  }
}

function checkLive(url, seconds) {
  return new Promise((resolve, reject) => {
    const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
    const client = new FoxgloveClient({ ws });
    const topics = {};
    const subscriptions = new Map();
    let server;
    let started = false;
    let closing = false;
    // Every handler fails the check (and drops the connection) at its first fault.
    const guard =
      (handler) =>
      (...args) => {
        try {
          handler(...args);
        } catch (e) {
          ws.terminate();
          reject(e);
        }
      };
    const hello = setTimeout(
      guard(() => fail(`no serverInfo and advertise from ${url} in ${HELLO_MS / 1000} s`)),
      HELLO_MS,
    );
    client.on(
      "open",
      guard(() => {
        if (ws.protocol !== FoxgloveClient.SUPPORTED_SUBPROTOCOL) {
          fail(`the server chose subprotocol '${ws.protocol}'`);
        }
      }),
    );
    client.on(
      "serverInfo",
      guard((info) => {
        server = { name: info.name, capabilities: info.capabilities };
      }),
    );
    client.on(
      "advertise",
      guard((channels) => {
        if (server === undefined) fail("advertise before serverInfo");
        for (const channel of channels) {
          const info = {
            topic: channel.topic,
            messageEncoding: channel.encoding,
            schemaName: channel.schemaName,
            schemaEncoding: channel.schemaEncoding ?? "",
            schemaText: channel.schema,
          };
          if (topics[info.topic]) fail(`two channels on ${info.topic}`);
          topics[info.topic] = tally(info);
          subscriptions.set(client.subscribe(channel.id), { info, decode: decoderFor(info) });
        }
        if (!started) {
          started = true;
          clearTimeout(hello);
          setTimeout(guard(finish), seconds * 1000);
        }
      }),
    );
    client.on(
      "message",
      guard(({ subscriptionId, timestamp, data }) => {
        const channel = subscriptions.get(subscriptionId);
        if (channel === undefined) fail(`a message for subscription ${subscriptionId}, unasked`);
        const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
        take(channel, topics, timestamp, bytes);
      }),
    );
    client.on(
      "error",
      guard((e) => fail(`WebSocket: ${e?.message ?? e}`)),
    );
    client.on(
      "close",
      guard((event) => {
        if (!closing) fail(`the server closed the connection (code ${event.code})`);
        resolve(summary(topics, { mode: "live", url, subprotocol: ws.protocol, server, seconds }));
      }),
    );
    function finish() {
      for (const id of subscriptions.keys()) client.unsubscribe(id);
      const silent = Object.keys(topics).filter((t) => topics[t].count === 0 && !ON_CHANGE.has(t));
      if (silent.length > 0) fail(`no messages in ${seconds} s on ${silent.join(", ")}`);
      closing = true;
      // Let the unsubscribes go out, then close; a server that does not answer the close frame
      // is cut off a second later.
      setTimeout(() => client.close(), 200);
      setTimeout(() => ws.terminate(), 1200).unref();
    }
  });
}

const [mode, target, secs] = process.argv.slice(2);
try {
  let result;
  if (mode === "file" && target) {
    result = await checkFile(target);
  } else if (mode === "live" && target && Number(secs) > 0) {
    result = await checkLive(target, Number(secs));
  } else {
    console.error("usage: node check.mjs file RUN.mcap | live ws://HOST:PORT SECONDS");
    process.exit(2);
  }
  console.log(JSON.stringify(result));
  process.exit(0);
} catch (e) {
  console.error(`foxglove-check: ${e?.message ?? e}`);
  process.exit(1);
}
