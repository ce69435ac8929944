//! DTMB signal-chain benchmarks: time per frame for generation (PN945, C = 3780, 64QAM),
//! a 6-path channel, frame sync (full search over one frame, and acquisition with frame
//! identification over two), and the full chain's real-time factor on one core.
//!
//! `cargo bench --bench dtmb -- --warm-up-time 1 --measurement-time 3`; figures in
//! docs/performance.md, section "DTMB".

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use hybridnav::core::{GpsTime, TrialRng};
use hybridnav::dtmb::{
    CarrierMode, Channel, ChannelConfig, FrameSchedule, Path, PnMode, Qam, Receiver, SampleSource,
    Search, SyncConfig, Transmitter, TxConfig, SAMPLE_RATE_HZ,
};
use num_complex::Complex32;
use std::time::Instant;

const MODE: PnMode = PnMode::Pn945;

fn transmitter() -> Transmitter {
    let cfg = TxConfig {
        schedule: FrameSchedule {
            mode: MODE,
            t0: GpsTime::from_ns(0),
            tower_clock_offset_s: 0.0,
        },
        carrier: CarrierMode::Multi3780,
        qam: Qam::Qam64,
        si_vector: 0,
    };
    Transmitter::new(cfg, &mut TrialRng::new(1, 0).stream("dtmb/tx"))
}

fn six_paths() -> ChannelConfig {
    // A typical urban profile plus an SFN co-channel tower 30 µs later; every path has its
    // own Doppler, as a moving receiver sees.
    let us = 1e-6;
    let paths = vec![
        Path::new(5.0 * us, 1.0, 0.0, 40.0),
        Path::new(5.3 * us, 0.6, 1.0, -25.0),
        Path::new(6.1 * us, 0.4, 2.0, 12.0),
        Path::new(7.9 * us, 0.3, 3.0, -38.0),
        Path::new(12.0 * us, 0.2, 4.0, 5.0),
        Path::new(35.0 * us, 0.5, 5.0, -15.0),
    ];
    ChannelConfig {
        paths,
        cfo_hz: 250.0,
        sfo_ppm: 1.5,
        snr_db: Some(5.0),
    }
}

fn bench(c: &mut Criterion) {
    let n = MODE.frame_len();
    let mut g = c.benchmark_group("dtmb_pn945_frame");
    g.throughput(Throughput::Elements(n as u64));

    let mut tx = transmitter();
    let mut out = vec![Complex32::default(); n];
    let mut k = 0i64;
    g.bench_function("generate", |b| {
        b.iter(|| {
            k += 1;
            tx.generate(k * n as i64, &mut out);
            black_box(&out);
        })
    });

    let mut ch = Channel::new(six_paths(), MODE, n).unwrap();
    let mut noise = TrialRng::new(1, 0).stream("dtmb/noise");
    let mut tx = transmitter();
    let mut k = 0i64;
    g.bench_function("channel_6_paths", |b| {
        b.iter(|| {
            k += 1;
            ch.process(&mut tx, k * n as i64, &mut out, &mut noise)
                .unwrap();
            black_box(&out);
        })
    });

    let len = n + MODE.header_len();
    let mut block = vec![Complex32::default(); len];
    let mut ch = Channel::new(six_paths(), MODE, 2 * n + MODE.header_len()).unwrap();
    ch.process(&mut tx, 20 * n as i64, &mut block, &mut noise)
        .unwrap();
    let mut rx = Receiver::new(MODE, len).unwrap();
    let full = SyncConfig {
        search: Search::Full {
            frame_in_superframe: Some(20),
        },
        ..SyncConfig::default()
    };
    g.bench_function("sync_full_search_one_frame", |b| {
        b.iter(|| black_box(rx.sync(&block, &full).unwrap()))
    });
    g.finish();

    let mut g = c.benchmark_group("dtmb_pn945_acquisition");
    let len2 = 2 * n + MODE.header_len();
    let mut block2 = vec![Complex32::default(); len2];
    ch.process(&mut tx, 40 * n as i64, &mut block2, &mut noise)
        .unwrap();
    let mut rx2 = Receiver::new(MODE, len2).unwrap();
    g.sample_size(10);
    g.bench_function("acquire_frame_number_two_frames", |b| {
        b.iter(|| black_box(rx2.sync(&block2, &SyncConfig::default()).unwrap()))
    });
    g.finish();

    // Full chain, one core: generate + 6-path channel + aided sync, frame by frame. The
    // channel block is a whole frame; the receiver tracks with a ±64-sample window.
    let frames = 400;
    let mut tx = transmitter();
    let mut ch = Channel::new(six_paths(), MODE, len).unwrap();
    let mut rx = Receiver::new(MODE, len).unwrap();
    let t = Instant::now();
    let mut sink = 0.0;
    for k in 0..frames {
        ch.process(&mut tx, (k * n) as i64, &mut block, &mut noise)
            .unwrap();
        let cfg = SyncConfig {
            search: Search::Aided {
                frame_in_superframe: k % MODE.frames_per_superframe(),
                predicted_start_samples: 38.0,
                half_window_samples: 64,
            },
            frames: 1,
            first_path: Some(Default::default()),
        };
        sink += rx.sync(&block, &cfg).unwrap().toa_samples;
    }
    let el = t.elapsed().as_secs_f64();
    let rate = (frames * n) as f64 / el;
    black_box(sink);
    println!(
        "dtmb full chain PN945 (generate + 6-path channel + sync), one core: {:.1} µs/frame, {:.2} Msps, real-time factor {:.1}",
        el / frames as f64 * 1e6,
        rate / 1e6,
        rate / SAMPLE_RATE_HZ
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
