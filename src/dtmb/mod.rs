//! DTMB (GB 20600-2006) signal chain.
