//! Who a request comes from ([`ClientKey`]) and each client's share of a budget the server shares
//! out ([`Shares`]): the bytes of document bodies being read, the pulls from peers in flight.
//!
//! A budget shared by everyone can be taken whole by one client — five stalled uploads of 32 MiB
//! held every document byte the server would read, and two studies of a slow peer every pull —
//! so each is also counted per client, and a client past its share is refused at once (429, its
//! own requests to blame) instead of making everyone else wait. A client is an IPv4 address, or
//! an IPv6 /64 (one host usually holds a whole /64, so counting single IPv6 addresses would give
//! it billions of shares).

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex};

/// A client, as budgets count them: an IPv4 address, or the /64 of an IPv6 address (IPv4-mapped
/// IPv6 counts as IPv4). `Unknown` for requests that did not come through the listener (tests
/// that call the router directly): they share one key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum ClientKey {
    /// An IPv4 address.
    V4([u8; 4]),
    /// The first 64 bits of an IPv6 address.
    V6(u64),
    /// Not known.
    #[default]
    Unknown,
}

impl ClientKey {
    /// The client of a peer address.
    pub fn of(ip: IpAddr) -> Self {
        match ip.to_canonical() {
            IpAddr::V4(v4) => ClientKey::V4(v4.octets()),
            IpAddr::V6(v6) => ClientKey::V6((u128::from(v6) >> 64) as u64),
        }
    }
}

impl std::fmt::Display for ClientKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ClientKey::V4(a) => write!(f, "{}", std::net::Ipv4Addr::from(*a)),
            ClientKey::V6(prefix) => {
                let net = std::net::Ipv6Addr::from(u128::from(*prefix) << 64);
                write!(f, "{net}/64")
            }
            ClientKey::Unknown => f.write_str("an unknown client"),
        }
    }
}

/// How much of a budget each client holds, and the most one may.
#[derive(Debug)]
pub struct Shares {
    per_client: usize,
    /// std Mutex: map operations only.
    held: Mutex<HashMap<ClientKey, usize>>,
}

/// What one request holds of its client's share; given back when dropped.
#[derive(Debug)]
pub struct Share {
    shares: Arc<Shares>,
    client: ClientKey,
    amount: usize,
}

impl Shares {
    /// A budget of which a client may hold at most `per_client`.
    pub fn new(per_client: usize) -> Arc<Self> {
        Arc::new(Self { per_client, held: Mutex::new(HashMap::new()) })
    }

    /// The most one client may hold.
    pub fn per_client(&self) -> usize {
        self.per_client
    }

    /// An empty share of `client`'s, to grow with [`Share::grow`].
    pub fn open(self: &Arc<Self>, client: ClientKey) -> Share {
        Share { shares: self.clone(), client, amount: 0 }
    }

    /// What `client` holds now.
    pub fn held_by(&self, client: ClientKey) -> usize {
        self.held.lock().expect("shares").get(&client).copied().unwrap_or(0)
    }
}

impl Share {
    /// Adds `n` to this share if its client stays within its share; false (nothing added) if not.
    pub fn grow(&mut self, n: usize) -> bool {
        let mut held = self.shares.held.lock().expect("shares");
        let now = held.entry(self.client).or_insert(0);
        if now.saturating_add(n) > self.shares.per_client {
            if *now == 0 {
                held.remove(&self.client);
            }
            return false;
        }
        *now += n;
        self.amount += n;
        true
    }

    /// The client whose share this is.
    pub fn client(&self) -> ClientKey {
        self.client
    }
}

impl Drop for Share {
    fn drop(&mut self) {
        if self.amount == 0 {
            return;
        }
        let mut held = self.shares.held.lock().expect("shares");
        if let Some(now) = held.get_mut(&self.client) {
            *now -= self.amount.min(*now);
            if *now == 0 {
                held.remove(&self.client);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_client_holds_at_most_its_share_and_gives_it_back() {
        let shares = Shares::new(10);
        let a = ClientKey::of("127.0.0.1".parse().unwrap());
        let b = ClientKey::of("127.0.0.2".parse().unwrap());
        let mut first = shares.open(a);
        assert!(first.grow(6));
        let mut second = shares.open(a);
        assert!(second.grow(4) && !second.grow(1), "a's share is spent");
        let mut other = shares.open(b);
        assert!(other.grow(10), "b has a share of its own");
        drop(first);
        assert_eq!(shares.held_by(a), 4);
        assert!(second.grow(6));
        drop((second, other));
        assert_eq!((shares.held_by(a), shares.held_by(b)), (0, 0));
        assert!(shares.held.lock().unwrap().is_empty(), "nothing left behind");
    }

    #[test]
    fn ipv6_clients_are_counted_by_their_64_bit_prefix() {
        let key = |s: &str| ClientKey::of(s.parse().unwrap());
        assert_eq!(key("2001:db8:1:2::1"), key("2001:db8:1:2:ffff::9"));
        assert_ne!(key("2001:db8:1:2::1"), key("2001:db8:1:3::1"));
        assert_eq!(key("::ffff:10.0.0.1"), key("10.0.0.1"));
        assert_eq!(key("2001:db8:1:2::1").to_string(), "2001:db8:1:2::/64");
        assert_eq!(key("10.0.0.1").to_string(), "10.0.0.1");
    }
}
