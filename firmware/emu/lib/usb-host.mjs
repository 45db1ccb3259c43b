// The USB host the emulated board is plugged into: it enumerates the device as an OS does
// (address, device and configuration descriptors, the manufacturer/product/serial strings,
// configuration), then behaves like Linux's cdc-acm driver for one CDC-ACM function:
// DTR and RTS are raised while a program holds the serial port open and dropped when it
// closes it, bulk IN packets are read only while the port is open, and bytes the program
// writes go out in bulk OUT packets whenever the device has a buffer armed.
//
// It replaces rp2040js's USBCDC helper, which answers every armed OUT buffer at once (with a
// zero-length packet when it has nothing to send: a flood the firmware must read), raises
// DTR as soon as the device is configured, whether or not anything listens, and reads no
// string descriptors. It relies on `holdDataEndpointBuffers` (fixes.mjs) for armed buffers
// that wait for the host. It does not own the bytes' meaning.

import { holdDataEndpointBuffers } from './fixes.mjs';

const PACKET = 64;
const DESCRIPTOR_DEVICE = 1;
const DESCRIPTOR_CONFIGURATION = 2;
const DESCRIPTOR_STRING = 3;
const DESCRIPTOR_INTERFACE = 4;
const DESCRIPTOR_ENDPOINT = 5;
const CLASS_CDC = 0x02;
const CLASS_CDC_DATA = 0x0a;
const CDC_SET_CONTROL_LINE_STATE = 0x22;
const LINE_DTR_RTS = 0b11;
/** US English, the language the firmware's strings are in. */
const LANG_EN_US = 0x0409;

function setup(requestType, request, value, index, length) {
  return Uint8Array.of(
    requestType,
    request,
    value & 0xff,
    value >> 8,
    index & 0xff,
    index >> 8,
    length & 0xff,
    length >> 8,
  );
}

const getDescriptor = (type, index, length, lang = 0) =>
  setup(0x80, 6, (type << 8) | index, lang, length);

/** The text of a string descriptor (UTF-16LE after the two header bytes). */
export function parseStringDescriptor(bytes) {
  const length = Math.min(bytes[0] ?? 0, bytes.length);
  let text = '';
  for (let i = 2; i + 1 < length; i += 2) {
    text += String.fromCharCode(bytes[i] | (bytes[i + 1] << 8));
  }
  return text;
}

/**
 * The CDC-ACM function in a configuration descriptor: the communication interface's number
 * and the data interface's bulk endpoints.
 */
export function findCdcAcm(config) {
  const found = { control: -1, in: -1, out: -1 };
  let cls = -1;
  for (let i = 0; i + 1 < config.length && config[i] >= 2; i += config[i]) {
    const type = config[i + 1];
    if (type === DESCRIPTOR_INTERFACE) {
      cls = config[i + 5];
      if (cls === CLASS_CDC && found.control < 0) {
        found.control = config[i + 2];
      }
    } else if (type === DESCRIPTOR_ENDPOINT && cls === CLASS_CDC_DATA && (config[i + 3] & 3) === 2) {
      const address = config[i + 2];
      if (address & 0x80) {
        found.in = address & 0x0f;
      } else {
        found.out = address & 0x0f;
      }
    }
  }
  return found;
}

export class UsbHost {
  /**
   * @param {import('rp2040js').RPUSBController} usb
   * @param {{ onData: (bytes: Uint8Array) => void,
   *           onEnumerated: (info: object) => void,
   *           log: (line: string) => void }} events
   */
  constructor(usb, events) {
    this.usb = usb;
    this.events = events;
    this.queue = [];
    this.current = null;
    this.cdc = null;
    this.configured = false;
    this.portOpen = false;
    // DTR/RTS last requested, and last acknowledged by the device.
    this.lineState = 0;
    this.lineStateDone = 0;
    this.toDevice = [];
    // OUT buffers the device armed (endpoint → length): it arms them while it handles
    // SET_CONFIGURATION, before that request completes. The IN packet armed on the CDC data
    // endpoint and not yet read.
    this.outArmed = new Map();
    this.inHeld = null;
    this.buffers = holdDataEndpointBuffers(usb, {
      onOutArmed: (endpoint, length) => {
        this.outArmed.set(endpoint, length);
        this.sendOut();
      },
      onInArmed: (endpoint, packet) => {
        if (this.cdc !== null && endpoint === this.cdc.in) {
          this.inHeld = packet;
          this.readIn();
        } else {
          // The notification endpoint: the cdc-acm driver polls it whenever the port is
          // open; nothing here needs its contents.
          this.buffers.completeIn(endpoint);
        }
      },
    });
    usb.onUSBEnabled = () => usb.resetDevice();
    usb.onResetReceived = () => this.enumerate();
    usb.onEndpointWrite = (endpoint, buffer) => {
      if (endpoint === 0) {
        this.controlIn(buffer);
      }
    };
    // Endpoint 0 OUT is armed for the status stage of IN requests; rp2040js completes it.
    usb.onEndpointRead = () => {};
  }

  /** A program opened (true) or closed (false) the serial port. */
  setPortOpen(open) {
    this.portOpen = open;
    if (!open) {
      this.toDevice = [];
    }
    this.applyLineState();
    this.readIn();
  }

  /** Bytes a program wrote to the serial port. */
  send(bytes) {
    for (const b of bytes) {
      this.toDevice.push(b);
    }
    this.sendOut();
  }

  enumerate() {
    this.queue = [];
    this.current = null;
    this.cdc = null;
    this.configured = false;
    this.lineState = 0;
    this.lineStateDone = 0;
    this.outArmed.clear();
    this.inHeld = null;
    const info = {};
    this.control(setup(0x00, 5, 1, 0, 0)); // SET_ADDRESS 1
    this.control(getDescriptor(DESCRIPTOR_DEVICE, 0, 18), (device) => {
      info.vid = device[8] | (device[9] << 8);
      info.pid = device[10] | (device[11] << 8);
      const strings = { manufacturer: device[14], product: device[15], serial: device[16] };
      this.control(getDescriptor(DESCRIPTOR_CONFIGURATION, 0, 9), (head) => {
        const total = head[2] | (head[3] << 8);
        this.control(getDescriptor(DESCRIPTOR_CONFIGURATION, 0, total), (config) => {
          const cdc = findCdcAcm(config);
          if (cdc.control < 0 || cdc.in < 0 || cdc.out < 0) {
            this.events.log(`usb: no CDC-ACM function in the configuration descriptor`);
          } else {
            this.cdc = cdc;
          }
          for (const [name, index] of Object.entries(strings)) {
            if (index === 0) {
              info[name] = null;
              continue;
            }
            this.control(getDescriptor(DESCRIPTOR_STRING, index, 255, LANG_EN_US), (s) => {
              info[name] = parseStringDescriptor(s);
            });
          }
          this.control(setup(0x00, 9, 1, 0, 0), () => {
            // SET_CONFIGURATION 1
            this.configured = true;
            this.events.onEnumerated(info);
            this.applyLineState();
            this.sendOut();
          });
        });
      });
    });
  }

  /** Queue a control transfer; `done(data)` runs when its last stage has completed. */
  control(packet, done = () => {}) {
    const length = (packet[0] & 0x80) !== 0 ? packet[6] | (packet[7] << 8) : 0;
    this.queue.push({ packet, length, data: [], done });
    this.nextControl();
  }

  nextControl() {
    if (this.current === null && this.queue.length > 0) {
      this.current = this.queue.shift();
      this.usb.sendSetupPacket(this.current.packet);
    }
  }

  controlIn(buffer) {
    const c = this.current;
    if (c === null) {
      return;
    }
    c.data.push(...buffer);
    // An IN request ends with a short packet or at its length; a request without a data
    // stage ends with the device's zero-length status packet.
    const finished = c.length === 0 ? buffer.length === 0 : c.data.length >= c.length || buffer.length < PACKET;
    if (finished) {
      this.current = null;
      c.done(Uint8Array.from(c.data));
      this.nextControl();
    }
  }

  applyLineState() {
    const wanted = this.portOpen ? LINE_DTR_RTS : 0;
    if (!this.configured || this.cdc === null || wanted === this.lineState) {
      return;
    }
    this.lineState = wanted;
    this.control(setup(0x21, CDC_SET_CONTROL_LINE_STATE, wanted, this.cdc.control, 0), () => {
      this.lineStateDone = wanted;
      this.sendOut();
    });
  }

  /** Bytes go out once the device has been told the port is open: on a real host a program
   *  opens the port (raising DTR) before it can write, and the port exists only once the
   *  device has enumerated. */
  sendOut() {
    const open = (this.lineStateDone & LINE_DTR_RTS) !== 0;
    if (!this.configured || this.cdc === null || !open || this.toDevice.length === 0) {
      return;
    }
    const armed = this.outArmed.get(this.cdc.out);
    if (armed === undefined) {
      return;
    }
    const packet = Uint8Array.from(this.toDevice.splice(0, Math.min(armed, PACKET, this.toDevice.length)));
    this.outArmed.delete(this.cdc.out);
    this.buffers.completeOut(this.cdc.out, packet);
  }

  readIn() {
    const packet = this.inHeld;
    if (packet === null || !this.portOpen) {
      return;
    }
    this.inHeld = null;
    this.buffers.completeIn(this.cdc.in);
    this.events.onData(packet);
  }
}
