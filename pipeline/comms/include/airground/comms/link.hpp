// The gossip's names for the datagram transport contract (drivers/net/link): the gossip sends over any
// DatagramLink: UDP on the robots' IP mesh, the simulator's radio model and an in-process hub for tests.
#pragma once

#include "airground/drivers/net/link/datagram_link.hpp"

namespace ag::comms {

using net::DatagramLink;
using net::LinkAddress;
using net::SendStatus;

}  // namespace ag::comms
