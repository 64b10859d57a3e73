"""The simulated rigs' addresses (sim.server): ports and ADS loopback addresses drawn so that rigs of
several test runs at once never collide."""
from sim.server import free_ads_address


def test_free_port_draws_below_the_ephemeral_range():
    """free_port's ports are ones the kernel never gives an outgoing connection (below
    ip_local_port_range), so no client socket can take one between the check and a server's bind;
    each is bindable when returned."""
    import socket

    from sim.server import PORT_RANGE, free_port
    with open("/proc/sys/net/ipv4/ip_local_port_range") as f:
        low = int(f.read().split()[0])
    ports = [free_port() for _ in range(30)]
    assert all(PORT_RANGE[0] <= p < low for p in ports), ports
    assert len(set(ports)) > 20  # drawn at random, not one fixed port
    for p in ports[:5]:
        with socket.socket() as s:
            s.bind(("127.0.0.1", p))


def test_free_ads_address_is_a_random_loopback_address_free_on_the_ads_port():
    """ADS servers on one machine share port 48898, so each simulated rig's takes its own loopback
    address: drawn at random over 127/8 (two test runs at once no longer both take 127.0.0.5), each
    bindable when returned, and one where a server listens is not free (the check binds as
    AdsTestServer does, with SO_REUSEADDR, which a listener still blocks)."""
    import ipaddress
    import socket

    from pyads.testserver.testserver import ADS_PORT

    from sim.server import _bindable
    hosts = [free_ads_address() for _ in range(30)]
    assert all(ipaddress.ip_address(h).is_loopback and not h.startswith("127.0.0.") for h in hosts), hosts
    assert len(set(hosts)) > 20
    with socket.socket() as listener:
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind((hosts[0], ADS_PORT))
        listener.listen()
        assert not _bindable(hosts[0], ADS_PORT, reuse_address=True)  # the check free_ads_address makes
    assert _bindable(hosts[0], ADS_PORT, reuse_address=True)  # and free again once the server is gone

