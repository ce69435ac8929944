//! MPEG-2 transport stream input for the data layer (ISO/IEC 13818-1): 188-byte packets
//! that start with the sync byte 0x47. A payload file is checked whole before use (a
//! length that is not a multiple of 188, or a packet without its sync byte, is refused
//! with the byte offset) and then streamed packet by packet, so its size does not bound
//! the memory; after its last packet the multiplex carries null packets (PID 0x1FFF), as
//! a multiplexer pads a constant-rate channel, never a repeat of the payload.

use super::DtmbError;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

/// Bytes of a TS packet.
pub const PACKET_LEN: usize = 188;
/// The sync byte.
pub const SYNC: u8 = 0x47;
/// Packets per read when a payload file is checked (≈ 1 MiB).
const CHECK_PACKETS: usize = 5577;
/// The PID of null packets.
pub const NULL_PID: u16 = 0x1fff;

/// A null packet: PID 0x1FFF, payload only, continuity counter 0 (undefined for null
/// packets, ISO/IEC 13818-1 §2.4.3.3), payload bytes 0xFF.
pub fn null_packet() -> [u8; PACKET_LEN] {
    let mut p = [0xffu8; PACKET_LEN];
    p[0] = SYNC;
    p[1] = 0x1f;
    p[2] = 0xff;
    p[3] = 0x10;
    p
}

/// Packet `index` of a pseudo-random transport stream keyed by `key`: sync byte, PID
/// 0x0100, payload only with the continuity counter `index mod 16`, then 184 bytes of
/// SplitMix64 (Steele, Lea & Flood, OOPSLA 2014) started from `mix(key ⊕ mix(index))`,
/// so any packet can be regenerated on its own.
pub fn pseudo_random_packet(key: u64, index: u64, out: &mut [u8]) {
    fn mix(mut z: u64) -> u64 {
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    out[0] = SYNC;
    out[1] = 0x01;
    out[2] = 0x00;
    out[3] = 0x10 | (index % 16) as u8;
    let mut state = mix(key ^ mix(index));
    for chunk in out[4..PACKET_LEN].chunks_mut(8) {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let w = mix(state).to_le_bytes();
        chunk.copy_from_slice(&w[..chunk.len()]);
    }
}

/// The PID of a packet.
pub fn pid(packet: &[u8]) -> u16 {
    (u16::from(packet[1] & 0x1f) << 8) | u16::from(packet[2])
}

/// Checks that `bytes` is a whole number of packets each starting with 0x47; the error
/// names the first offending byte offset.
pub fn check_packets(bytes: &[u8], origin: &str) -> Result<(), DtmbError> {
    check_chunk(bytes, 0, origin)?;
    if bytes.len() % PACKET_LEN != 0 {
        return Err(misaligned(origin, bytes.len() as u64));
    }
    Ok(())
}

fn misaligned(origin: &str, len: u64) -> DtmbError {
    let last = len - len % PACKET_LEN as u64;
    DtmbError::Ts {
        path: origin.to_string(),
        reason: format!(
            "{len} bytes is not a whole number of 188-byte packets: the packet at byte offset \
             {last} has only {} bytes",
            len - last
        ),
    }
}

fn check_chunk(bytes: &[u8], base: u64, origin: &str) -> Result<(), DtmbError> {
    for (i, p) in bytes.chunks(PACKET_LEN).enumerate() {
        if p[0] != SYNC {
            return Err(DtmbError::Ts {
                path: origin.to_string(),
                reason: format!(
                    "byte offset {}: expected the sync byte 0x47, found {:#04x} (not a 188-byte \
                     aligned MPEG-TS)",
                    base + (i * PACKET_LEN) as u64,
                    p[0]
                ),
            });
        }
    }
    Ok(())
}

/// The packets a transmitter sends: a payload's, then null packets.
pub struct PacketSource {
    reader: Option<(PathBuf, BufReader<std::fs::File>)>,
    /// The key of [`pseudo_random_packet`] when the packets are generated, not read.
    generated: Option<u64>,
    payload_packets: u64,
    null_packets: u64,
}

impl std::fmt::Debug for PacketSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PacketSource")
            .field("payload_packets", &self.payload_packets)
            .field("null_packets", &self.null_packets)
            .finish_non_exhaustive()
    }
}

impl PacketSource {
    /// Only null packets.
    pub fn null() -> Self {
        Self {
            reader: None,
            generated: None,
            payload_packets: 0,
            null_packets: 0,
        }
    }

    /// An endless stream of [`pseudo_random_packet`]s of `key` (packet `i` the `i`-th
    /// sent), for error-rate measurements: a receiver regenerates what was sent.
    pub fn pseudo_random(key: u64) -> Self {
        Self {
            generated: Some(key),
            ..Self::null()
        }
    }

    /// A payload file, checked whole (streamed in reads of 5577 packets, ≈ 1 MiB) before
    /// it is used.
    ///
    /// # Errors
    /// [`DtmbError::Io`] when it cannot be read, [`DtmbError::Ts`] when it is empty, not a
    /// whole number of packets or a packet lacks its sync byte.
    pub fn from_file(path: &Path) -> Result<Self, DtmbError> {
        let origin = path.display().to_string();
        let io = |e| DtmbError::Io {
            path: origin.clone(),
            source: e,
        };
        // A regular file of bounded size (a pipe or device would block or never end).
        let (f, _) = crate::io::read::open(path, crate::io::read::TS_PAYLOAD).map_err(io)?;
        let mut f = BufReader::new(f);
        // A whole number of packets, so every chunk starts on a packet boundary (a 1 MiB
        // buffer, not a multiple of 188, made every payload over 1 MiB look unsynced).
        let mut buf = vec![0u8; CHECK_PACKETS * PACKET_LEN];
        let mut total = 0u64;
        loop {
            // Fill the buffer fully (short reads happen) so chunks stay packet-aligned.
            let mut n = 0;
            while n < buf.len() {
                let k = f.read(&mut buf[n..]).map_err(io)?;
                if k == 0 {
                    break;
                }
                n += k;
            }
            if n == 0 {
                break;
            }
            check_chunk(&buf[..n], total, &origin)?;
            total += n as u64;
            if n < buf.len() {
                break;
            }
        }
        if total == 0 {
            return Err(DtmbError::Ts {
                path: origin,
                reason: "the payload is empty (0 packets)".into(),
            });
        }
        if total % PACKET_LEN as u64 != 0 {
            return Err(misaligned(&origin, total));
        }
        let (f, _) = crate::io::read::open(path, crate::io::read::TS_PAYLOAD).map_err(io)?;
        Ok(Self {
            reader: Some((path.to_path_buf(), BufReader::with_capacity(1 << 16, f))),
            generated: None,
            payload_packets: 0,
            null_packets: 0,
        })
    }

    /// Writes the next packet into `out`.
    ///
    /// # Errors
    /// [`DtmbError::Io`] when the payload file fails to read.
    pub fn next_packet(&mut self, out: &mut [u8]) -> Result<(), DtmbError> {
        if let Some(key) = self.generated {
            pseudo_random_packet(key, self.payload_packets, &mut out[..PACKET_LEN]);
            self.payload_packets += 1;
            return Ok(());
        }
        if let Some((path, r)) = &mut self.reader {
            let mut n = 0;
            while n < PACKET_LEN {
                let k = r.read(&mut out[n..PACKET_LEN]).map_err(|e| DtmbError::Io {
                    path: path.display().to_string(),
                    source: e,
                })?;
                if k == 0 {
                    break;
                }
                n += k;
            }
            if n == PACKET_LEN {
                self.payload_packets += 1;
                return Ok(());
            }
            // The file was checked whole: a short read is its end.
            self.reader = None;
        }
        out[..PACKET_LEN].copy_from_slice(&null_packet());
        self.null_packets += 1;
        Ok(())
    }

    /// Payload packets sent so far.
    pub fn payload_packets(&self) -> u64 {
        self.payload_packets
    }

    /// Null packets sent so far.
    pub fn null_packets(&self) -> u64 {
        self.null_packets
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn misaligned_and_unsynced_streams_are_refused_with_the_offset() {
        let mut b = Vec::new();
        for _ in 0..3 {
            b.extend_from_slice(&null_packet());
        }
        assert!(check_packets(&b, "x").is_ok());
        b[376] = 0x00;
        let e = check_packets(&b, "x").unwrap_err().to_string();
        assert!(e.contains("byte offset 376"), "{e}");
        b[376] = SYNC;
        b.truncate(500);
        let e = check_packets(&b, "x").unwrap_err().to_string();
        assert!(
            e.contains("byte offset 376") && e.contains("124 bytes"),
            "{e}"
        );
    }

    #[test]
    fn a_file_payload_is_followed_by_null_packets() {
        let d = std::env::temp_dir().join(format!("hybridnav-ts-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let p = d.join("a.ts");
        let mut pkt = null_packet();
        pkt[1] = 0x01;
        pkt[4] = 0xab;
        std::fs::write(&p, [pkt, pkt].concat()).unwrap();
        let mut s = PacketSource::from_file(&p).unwrap();
        let mut out = [0u8; PACKET_LEN];
        s.next_packet(&mut out).unwrap();
        assert_eq!(out, pkt);
        s.next_packet(&mut out).unwrap();
        s.next_packet(&mut out).unwrap();
        assert_eq!(pid(&out), NULL_PID);
        assert_eq!((s.payload_packets(), s.null_packets()), (2, 1));
        std::fs::write(&p, &pkt[..100]).unwrap();
        let e = PacketSource::from_file(&p).unwrap_err().to_string();
        assert!(
            e.contains("byte offset 0") && e.contains("100 bytes"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A payload longer than one check read (here 2.5 reads) is accepted and streamed
    /// whole; a bad sync byte in its second read is reported at its own offset.
    #[test]
    fn a_payload_longer_than_one_check_read_is_accepted() {
        let d = std::env::temp_dir().join(format!("hybridnav-ts-long-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let p = d.join("long.ts");
        let n = CHECK_PACKETS * 5 / 2;
        let mut bytes = Vec::with_capacity(n * PACKET_LEN);
        for i in 0..n {
            let mut pkt = null_packet();
            pkt[1] = 0x01;
            pkt[4..12].copy_from_slice(&(i as u64).to_le_bytes());
            bytes.extend_from_slice(&pkt);
        }
        std::fs::write(&p, &bytes).unwrap();
        let mut s = PacketSource::from_file(&p).unwrap();
        let mut out = [0u8; PACKET_LEN];
        for i in 0..n {
            s.next_packet(&mut out).unwrap();
            assert_eq!(u64::from_le_bytes(out[4..12].try_into().unwrap()), i as u64);
        }
        s.next_packet(&mut out).unwrap();
        assert_eq!(pid(&out), NULL_PID);
        let bad = (CHECK_PACKETS + 7) * PACKET_LEN;
        bytes[bad] = 0x00;
        std::fs::write(&p, &bytes).unwrap();
        let e = PacketSource::from_file(&p).unwrap_err().to_string();
        assert!(e.contains(&format!("byte offset {bad}:")), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }
}
