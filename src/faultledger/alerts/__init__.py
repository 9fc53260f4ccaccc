"""Alert delivery in a serving process (docs/alerts.md): the threads that scan the log into
the outbox and send each rule's deliveries to its receiver."""
