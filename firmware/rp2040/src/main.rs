//! Bench firmware for a Raspberry Pi Pico (RP2040): runs `mpc-firmware-core`'s [`Device`]
//! with embassy-rp. USB CDC-ACM serial to the host with the flash's unique ID as serial
//! number, STEP/DIR/EN on GPIO outputs timed by the 1 MHz system timer, two blocking I²C
//! buses for the sensors, a software quadrature decoder on two GPIO inputs, and an e-stop
//! input. Pin map and wiring: `firmware/README.md`. Logs go out as defmt frames over RTT.
//!
//! One loop owns the device: it sleeps until the device's next deadline (next step, next
//! sample, watchdog), a USB packet or an e-stop edge, polls the device, and writes queued
//! frames with a short timeout so a host that stops reading cannot stall the steps (the
//! device then drops and counts sample batches). Frames go out only while a program holds
//! the port open (DTR set, as Linux, macOS and Windows set it on open); otherwise they are
//! dropped, so that stale frames do not greet the next host.
#![no_std]
#![no_main]

use core::sync::atomic::{AtomicI32, Ordering};

use defmt::{info, warn};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_futures::select::{select, select3, Either3};
use embassy_rp::bind_interrupts;
use embassy_rp::flash::{self, Flash};
use embassy_rp::gpio::{Input, Level, Output, Pull};
use embassy_rp::i2c::{self, Blocking, I2c};
use embassy_rp::peripherals::{I2C0, I2C1, USB};
use embassy_rp::usb::{Driver, InterruptHandler};
use embassy_time::{with_timeout, Delay, Duration, Instant, Timer};
use embassy_usb::class::cdc_acm::{CdcAcmClass, State};
use embassy_usb::{Builder, UsbDevice};
use mpc_firmware_core::sensors::quadrature::QuadratureDecoder;
use mpc_firmware_core::{
    BoardConfig, Clock, Device, Parts, Platform, QuadratureCounter, SerialNumber,
};
use mpc_wire::SensorSet;
use panic_probe as _;
use static_cell::StaticCell;

bind_interrupts!(struct Irqs {
    USBCTRL_IRQ => InterruptHandler<USB>;
});

/// Board facts announced in the handshake. 20 kHz: the step rate this single loop keeps
/// with 1 kHz sampling of three I²C sensors at 400 kHz (each sample blocks ≈ 0.4 ms, which
/// delays, but never loses, the steps due meanwhile).
const BOARD: BoardConfig = BoardConfig::new(
    "rp2040-pico",
    SensorSet::ENCODER_A
        .union(SensorSet::ENCODER_B)
        .union(SensorSet::QUADRATURE)
        .union(SensorSet::IMU),
    20_000,
);

/// I²C clock, Hz: 400 kHz Fast-mode, the BNO055's maximum (the AS5600 allows 1 MHz).
const I2C_HZ: u32 = 400_000;

/// USB vendor/product id: Raspberry Pi's VID with the Pico SDK's CDC product id, which
/// every OS binds to its CDC-ACM driver without setup.
const USB_VID_PID: (u16, u16) = (0x2E8A, 0x000A);

/// Longest wait for the host to take one 64-byte packet, ms. Default 2 ms: a reading host
/// takes a packet every 1 ms frame; longer waits would delay steps.
const USB_WRITE_TIMEOUT_MS: u64 = 2;

/// Longest sleep when the device has no deadline, ms: how soon a change of DTR (a program
/// opening or closing the port) is noticed.
const IDLE_POLL_MS: u64 = 10;

/// Size of the Pico's QSPI flash (W25Q16JV), bytes.
const FLASH_SIZE: usize = 2 * 1024 * 1024;

defmt::timestamp!("{=u64:us}", Instant::now().as_micros());

/// Quadrature count published by the decoder task, read by the device.
static QUADRATURE: AtomicI32 = AtomicI32::new(0);

struct TimerClock;
impl Clock for TimerClock {
    fn now_us(&self) -> u64 {
        Instant::now().as_micros()
    }
}

struct SharedQuadrature;
impl QuadratureCounter for SharedQuadrature {
    fn count(&mut self) -> i32 {
        QUADRATURE.load(Ordering::Relaxed)
    }
}

struct Pico;
impl Platform for Pico {
    type I2cA = I2c<'static, I2C0, Blocking>;
    type I2cB = I2c<'static, I2C1, Blocking>;
    type Step = Output<'static>;
    type Dir = Output<'static>;
    type Enable = Output<'static>;
    type Delay = Delay;
    type Clock = TimerClock;
    type Quadrature = SharedQuadrature;
}

type UsbDriver = Driver<'static, USB>;

#[embassy_executor::task]
async fn usb_task(mut usb: UsbDevice<'static, UsbDriver>) -> ! {
    usb.run().await
}

/// Software 4× quadrature decoding on pin-change events (for slow encoders: edges closer
/// together than the loop's I²C transactions can be missed; a PIO program would not).
#[embassy_executor::task]
async fn quadrature_task(mut a: Input<'static>, mut b: Input<'static>) -> ! {
    let mut decoder = QuadratureDecoder::new(a.is_high(), b.is_high());
    loop {
        select(a.wait_for_any_edge(), b.wait_for_any_edge()).await;
        decoder.update(a.is_high(), b.is_high());
        QUADRATURE.store(decoder.count(), Ordering::Relaxed);
    }
}

/// The USB serial number: the flash chip's unique ID in hex (see `SerialNumber`).
fn serial_number(flash: embassy_rp::peripherals::FLASH) -> SerialNumber {
    let mut flash = Flash::<_, flash::Blocking, FLASH_SIZE>::new_blocking(flash);
    let mut id = [0u8; 8];
    match flash.blocking_unique_id(&mut id) {
        Ok(()) => SerialNumber::from_unique_id(id),
        Err(_) => {
            warn!("cannot read the flash unique ID; serial number 0000000000000000");
            SerialNumber::from_unique_id([0; 8])
        }
    }
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_rp::init(Default::default());

    // Driver pins first, in their safe state: EN high = disabled (active low).
    let enable = Output::new(p.PIN_12, Level::High);
    let step = Output::new(p.PIN_10, Level::Low);
    let dir = Output::new(p.PIN_11, Level::Low);
    // The e-stop button: a normally closed contact to ground. Pressed, or its wire broken,
    // the pull-up takes the pin high.
    let mut estop = Input::new(p.PIN_13, Pull::Up);

    static SERIAL: StaticCell<SerialNumber> = StaticCell::new();
    let serial = SERIAL.init(serial_number(p.FLASH));
    info!(
        "mpc-bench-rp2040 booting, USB serial number {=str}",
        serial.as_str()
    );

    let mut i2c_config = i2c::Config::default();
    i2c_config.frequency = I2C_HZ;
    let i2c_a = I2c::new_blocking(p.I2C0, p.PIN_5, p.PIN_4, i2c_config);
    let mut i2c_config = i2c::Config::default();
    i2c_config.frequency = I2C_HZ;
    let i2c_b = I2c::new_blocking(p.I2C1, p.PIN_7, p.PIN_6, i2c_config);

    let quad_a = Input::new(p.PIN_14, Pull::Up);
    let quad_b = Input::new(p.PIN_15, Pull::Up);
    spawner.must_spawn(quadrature_task(quad_a, quad_b));

    // USB CDC-ACM.
    let driver = Driver::new(p.USB, Irqs);
    let mut usb_config = embassy_usb::Config::new(USB_VID_PID.0, USB_VID_PID.1);
    usb_config.manufacturer = Some("mpc-rig");
    usb_config.product = Some("mpc bench (rp2040)");
    usb_config.serial_number = Some(serial.as_str());
    usb_config.max_power = 100;
    usb_config.max_packet_size_0 = 64;
    static CONFIG_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static BOS_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static CONTROL_BUF: StaticCell<[u8; 64]> = StaticCell::new();
    static CDC_STATE: StaticCell<State> = StaticCell::new();
    let mut builder = Builder::new(
        driver,
        usb_config,
        CONFIG_DESC.init([0; 256]),
        BOS_DESC.init([0; 256]),
        &mut [],
        CONTROL_BUF.init([0; 64]),
    );
    let mut class = CdcAcmClass::new(&mut builder, CDC_STATE.init(State::new()), 64);
    spawner.must_spawn(usb_task(builder.build()));

    static DEVICE: StaticCell<Device<Pico>> = StaticCell::new();
    let device = DEVICE.init(Device::new(
        Parts {
            i2c_a,
            i2c_b,
            step,
            dir,
            enable,
            delay: Delay,
            clock: TimerClock,
            quadrature: SharedQuadrature,
        },
        BOARD,
    ));

    let mut rx = [0u8; 64];
    let mut tx = [0u8; 64];
    // The host has configured the device (its endpoints are enabled).
    let mut configured = false;
    let mut was_connected = false;
    loop {
        let wake = device
            .next_deadline_us()
            .map(Instant::from_micros)
            .unwrap_or_else(|| Instant::now() + Duration::from_millis(IDLE_POLL_MS));
        let edge = estop.wait_for_any_edge();
        if configured {
            match select3(class.read_packet(&mut rx), Timer::at(wake), edge).await {
                Either3::First(Ok(n)) => device.receive(&rx[..n]),
                Either3::First(Err(_)) => configured = false,
                Either3::Second(()) | Either3::Third(()) => {}
            }
        } else if let Either3::First(()) =
            select3(class.wait_connection(), Timer::at(wake), edge).await
        {
            configured = true;
        }
        device.set_estop_input(estop.is_high());
        device.poll();
        let connected = configured && class.dtr();
        if connected != was_connected {
            was_connected = connected;
            info!(
                "host {=str} the port",
                if connected { "opened" } else { "closed" }
            );
        }
        if connected {
            // Send what is queued, one packet at a time, never waiting long.
            while device.pending_output() > 0 {
                let n = device.peek_output(&mut tx);
                let timeout = Duration::from_millis(USB_WRITE_TIMEOUT_MS);
                match with_timeout(timeout, class.write_packet(&tx[..n])).await {
                    Ok(Ok(())) => {
                        device.consume_output(n);
                        if n == tx.len() && device.pending_output() == 0 {
                            // A full packet ends a transfer only with a zero-length packet.
                            let _ = with_timeout(timeout, class.write_packet(&[])).await;
                        }
                    }
                    Ok(Err(_)) => {
                        configured = false;
                        break;
                    }
                    Err(_) => break,
                }
                device.poll();
            }
        } else {
            // Nobody listens: drop output so that stale frames do not greet the next host.
            let n = device.pending_output();
            device.consume_output(n);
        }
    }
}
