"""The requester side of the crowd: publishing tasks as HITs, collecting and paying work."""
