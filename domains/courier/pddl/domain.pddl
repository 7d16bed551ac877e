;; cbdi's courier domain: robots carry parcels to their destinations across an office
;; floor. Driving drains a robot's battery, a dock charges it; doors close on their own
;; and a robot must open one before driving through; a cart rolls along the corridor.
;; A drive needs its target cell open for its whole length: a door that closes while a
;; robot drives into it makes the drive fail. A robot does one thing at a time (idle).
;; Cells are named c_X_Y.

(define (domain courier)
  (:requirements :strips :typing :fluents :durative-actions :negative-preconditions)

  (:types robot parcel cell)

  (:predicates
    (at ?r - robot ?c - cell)             ; where a robot is
    (clear ?c - cell)                     ; no robot or cart stands there
    (open ?c - cell)                      ; a corridor cell, or a door that is open
    (link ?c1 - cell ?c2 - cell)          ; 4-adjacent floor cells
    (dock ?c - cell)                      ; a charging dock
    (parcel_at ?p - parcel ?c - cell)
    (destination ?p - parcel ?c - cell)
    (carrying ?r - robot ?p - parcel)
    (empty ?r - robot)
    (delivered ?p - parcel)
    (charged ?r - robot)
    (idle ?r - robot))                    ; doing nothing: one action at a time

  (:functions
    (battery ?r - robot)                  ; charge left, one unit per drive
    (capacity ?r - robot))

  (:durative-action drive
    :parameters (?r - robot ?from ?to - cell)
    :duration (= ?duration 2)
    :condition (and (at start (idle ?r))
                    (at start (at ?r ?from))
                    (at start (link ?from ?to))
                    (at start (clear ?to))
                    (at start (>= (battery ?r) 1))
                    (over all (open ?to)))
    :effect (and (at start (not (idle ?r)))
                 (at end (idle ?r))
                 (at start (not (clear ?to)))
                 (at start (not (charged ?r)))
                 (at start (decrease (battery ?r) 1))
                 (at end (not (at ?r ?from)))
                 (at end (clear ?from))
                 (at end (at ?r ?to))))

  (:durative-action open_door
    :parameters (?r - robot ?from ?door - cell)
    :duration (= ?duration 1)
    :condition (and (at start (idle ?r))
                    (at start (at ?r ?from))
                    (at start (link ?from ?door))
                    (at start (not (open ?door))))
    :effect (and (at start (not (idle ?r)))
                 (at end (idle ?r))
                 (at end (open ?door))))

  (:durative-action grab
    :parameters (?r - robot ?p - parcel ?c - cell)
    :duration (= ?duration 1)
    :condition (and (at start (idle ?r))
                    (at start (at ?r ?c))
                    (at start (parcel_at ?p ?c))
                    (at start (empty ?r)))
    :effect (and (at start (not (idle ?r)))
                 (at end (idle ?r))
                 (at start (not (parcel_at ?p ?c)))
                 (at start (not (empty ?r)))
                 (at end (carrying ?r ?p))))

  (:durative-action drop
    :parameters (?r - robot ?p - parcel ?c - cell)
    :duration (= ?duration 1)
    :condition (and (at start (idle ?r))
                    (at start (at ?r ?c))
                    (at start (carrying ?r ?p))
                    (at start (destination ?p ?c)))
    :effect (and (at start (not (idle ?r)))
                 (at end (idle ?r))
                 (at start (not (carrying ?r ?p)))
                 (at end (delivered ?p))
                 (at end (empty ?r))))

  (:durative-action charge
    :parameters (?r - robot ?c - cell)
    :duration (= ?duration 4)
    :condition (and (at start (idle ?r))
                    (at start (at ?r ?c))
                    (at start (dock ?c)))
    :effect (and (at start (not (idle ?r)))
                 (at end (idle ?r))
                 (at end (assign (battery ?r) (capacity ?r)))
                 (at end (charged ?r))))
)
