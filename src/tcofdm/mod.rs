//! TC-OFDM base stations (seed 004): ranging signals from time-synchronised base stations.
